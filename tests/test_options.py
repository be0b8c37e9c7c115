"""The solver's options are written once (emu.options.OPTIONS): the Solver's
signature, the scene-file schema and the docs' options page come from it; an
unknown option names the nearest one, and an option of the other method (or
of another EMU step) is an error naming it."""
import dataclasses
import inspect
import json
from pathlib import Path

import numpy as np

import pytest

import emu
from emu.app.scenefile import _SCHEMA
from emu.solve.options import OPTIONS, options_markdown

ROOT = Path(__file__).resolve().parents[1]


def test_the_signature_and_the_scene_file_schema_come_from_the_table():
    params = inspect.signature(emu.Solver).parameters
    assert [p for p in params if p not in ("scene", "method", "groups")] == list(OPTIONS)
    assert all(params[n].default == o.default for n, o in OPTIONS.items())
    assert set(_SCHEMA["solver"]) == set(OPTIONS) - {"single_precision_s0"} | {"method"}
    for name, o in OPTIONS.items():
        assert f"{name} = {o.default!r}" in emu.Solver.__doc__


def test_the_docs_options_page_is_current():
    assert (ROOT / "docs" / "guide" / "options.md").read_text() == options_markdown(), \
        "regenerate it: the command is on the page"


def test_defaults_come_from_the_table():
    scene = emu.scenes.fusiform(2, warn=False)
    s = emu.Solver(scene, "emu", alpha=100)
    assert s.settings["rtol_grad"] == OPTIONS["rtol_grad"].default
    assert s.settings["position_tol"] == OPTIONS["position_tol"].default
    assert s.settings["step_fraction"] == OPTIONS["step_fraction"].default


@pytest.mark.parametrize("method, kw, message", [
    ("emu", {"alfa": 100}, "unknown solver option 'alfa' \\(did you mean 'alpha'\\?\\)"),
    ("fem", {"alpha": 100}, "alpha is an option of EMU only; leave it out for method='fem'"),
    ("fem", {"modes": 12}, "modes is an option of EMU only"),
    ("emu", {"lagged_factor": True}, "lagged_factor is an option of FEM only; leave it out for method='emu'"),
    ("emu", {"negative_curvature": False}, "negative_curvature is an option of FEM only"),
    ("emu", {"step": "lbfgs", "preconditioner": "schur"}, "preconditioner applies to EMU's newton-krylov step only"),
    ("emu", {"lbfgs_memory": 4}, "lbfgs_memory applies to EMU's lbfgs step only"),
])
def test_an_option_that_does_not_apply_is_named(method, kw, message):
    scene = emu.scenes.fusiform(2, warn=False)
    with pytest.raises(ValueError, match=message):
        emu.Solver(scene, method, **kw)


def test_an_option_at_its_default_passes_for_either_method():
    """A loop over both methods may pass the same options at their defaults."""
    scene = emu.scenes.fusiform(2, warn=False)
    for method in ("emu", "fem"):
        emu.Solver(scene, method, lagged_factor=False, error_estimate=True, threads=None)


def test_emu_solve_and_scene_files_check_the_same_way(tmp_path):
    scene = emu.scenes.fusiform(2, warn=False)
    with pytest.raises(ValueError, match="alpha is an option of EMU only"):
        emu.solve(scene, {"belly": 0.1}, "fem", normalized=True, alpha=100)
    from emu import SceneFileError, load_scene_file
    from test_scenefile import GOOD

    (tmp_path / "s.toml").write_text(GOOD.replace("alpha = 100.0", "alpha = 100.0\nlagged_factor = true"))
    with pytest.raises(SceneFileError, match="solver.lagged_factor is an option of FEM only"):
        load_scene_file(tmp_path / "s.toml")
    (tmp_path / "t.toml").write_text(GOOD.replace("alpha = 100.0", "alpha = \"high\""))
    with pytest.raises(SceneFileError, match="solver.alpha"):
        load_scene_file(tmp_path / "t.toml")


def test_choices_are_spelled_once_in_the_core():
    """The C++ options take and give the names Python, scene files and the CLI use."""
    from emu import _core
    from emu.solve.options import CHOICES

    assert CHOICES["step"] == ("newton-krylov", "woodbury", "lbfgs")
    assert CHOICES["eigen_filter"] == ("clamp", "abs")
    assert set(CHOICES["preconditioner"]) == {"constant-schur", "schur", "woodbury"}
    eo, so = _core.EmuSolverOptions(), _core.SolverOptions()
    assert (eo.step, eo.preconditioner, so.eigen_filter) == ("newton-krylov", "constant-schur", "clamp")
    for name in CHOICES["preconditioner"]:
        eo.preconditioner = name
        assert eo.preconditioner == name
    so.eigen_filter = "abs"
    assert so.eigen_filter == "abs"
    with pytest.raises(ValueError, match="step must be one of 'newton-krylov', 'woodbury', 'lbfgs', got 'newton_krylov'"):
        eo.step = "newton_krylov"
    for name in ("step", "preconditioner", "eigen_filter"):
        assert OPTIONS[name].default == CHOICES[name][0]


@pytest.mark.parametrize("kw, message", [
    ({"step": "newton_krylov"}, "step must be one of 'newton-krylov', 'woodbury', 'lbfgs', got 'newton_krylov'"),
    ({"preconditioner": "constant_schur"}, "preconditioner must be one of"),
    ({"eigen_filter": 1}, "eigen_filter must be one of 'clamp', 'abs', got 1"),
])
def test_a_choice_that_is_not_one_is_named(kw, message):
    with pytest.raises(ValueError, match=message):
        emu.Solver(emu.scenes.fusiform(2, warn=False), "emu", **kw)


def test_option_groups_are_the_tables_groups():
    from emu.solve.options import GROUP_CLASSES, GROUPS

    grouped = [f.name for cls in GROUP_CLASSES for f in dataclasses.fields(cls)]
    assert sorted(grouped) == sorted(n for n, o in OPTIONS.items() if o.group in {c.group for c in GROUP_CLASSES}
                                     and n != "single_precision_s0")
    assert set(GROUPS) - {c.group for c in GROUP_CLASSES} == {"machine"}
    for cls in GROUP_CLASSES:
        for f in dataclasses.fields(cls):
            assert OPTIONS[f.name].group == cls.group and f.default == OPTIONS[f.name].default
            assert f"{f.name} = " in cls.__doc__
    with pytest.raises(TypeError, match="rtol_grd"):
        emu.StoppingOptions(rtol_grd=1e-8)
    with pytest.raises(ValueError, match="step must be one of"):
        emu.EmuOptions(step="newton_krylov")


def test_option_groups_set_the_solver_as_keywords_do():
    scene = emu.scenes.fusiform(2, warn=False)
    by_group = emu.Solver(scene, "emu", emu.StoppingOptions(rtol_grad=1e-8, max_iterations=77),
                          emu.EmuOptions(alpha=50.0, step="lbfgs", lbfgs_memory=5), emu.NewtonOptions(eigen_filter="abs"))
    by_keyword = emu.Solver(scene, "emu", rtol_grad=1e-8, max_iterations=77, alpha=50.0, step="lbfgs", lbfgs_memory=5,
                            eigen_filter="abs")
    assert by_group.settings == by_keyword.settings
    assert by_group.settings["eigen_filter"] == "abs" and by_group.settings["max_iterations"] == 77
    # the method may be left out; a group of the other method at its defaults changes nothing
    assert emu.Solver(scene, emu.StoppingOptions(rtol_grad=1e-8), emu.FemOptions()).method == "emu"
    act = {"belly": 0.2}
    a = emu.solve(scene, act, "fem", emu.StoppingOptions(rtol_grad=1e-9), normalized=True)
    b = emu.solve(scene, act, "fem", rtol_grad=1e-9, normalized=True)
    assert a.iterations == b.iterations and np.array_equal(a.positions, b.positions)


@pytest.mark.parametrize("groups, kw, message", [
    ((emu.StoppingOptions(rtol_grad=1e-8),), {"rtol_grad": 1e-7}, "rtol_grad is given twice"),
    ((emu.StoppingOptions(), emu.StoppingOptions()), {}, "StoppingOptions is given twice"),
    (({"rtol_grad": 1e-8},), {}, "passed by keyword or as option groups"),
])
def test_an_option_given_twice_is_refused(groups, kw, message):
    with pytest.raises(TypeError, match=message):
        emu.Solver(emu.scenes.fusiform(2, warn=False), "emu", *groups, **kw)


def test_an_emu_group_option_is_refused_for_fem():
    with pytest.raises(ValueError, match="alpha is an option of EMU only"):
        emu.Solver(emu.scenes.fusiform(2, warn=False), "fem", emu.EmuOptions(alpha=50.0))


@pytest.mark.parametrize("text, expected", [
    ("rtol_grad=1e-8", ("rtol_grad", 1e-8)), ("max_iterations=40", ("max_iterations", 40)),
    ("max_iterations=none", ("max_iterations", None)), ("lagged_factor=true", ("lagged_factor", True)),
    ("error_estimate=off", ("error_estimate", False)), ("eigen_filter=abs", ("eigen_filter", "abs")),
    ("alpha=200", ("alpha", 200)),
])
def test_parse_option_reads_the_tables_type(text, expected):
    from emu.solve.options import parse_option

    assert parse_option(text) == expected


@pytest.mark.parametrize("text, message", [
    ("rtol_grd=1e-8", "did you mean 'rtol_grad'"), ("rtol_grad", "NAME=VALUE"),
    ("threads=two", "threads takes int or none, got 'two'"), ("lagged_factor=maybe", "true/false"),
])
def test_parse_option_names_the_problem(text, message):
    from emu.solve.options import parse_option

    with pytest.raises(ValueError, match=message):
        parse_option(text)


def test_the_cli_takes_any_option(tmp_path, capsys):
    from emu.app.cli import main

    scene_file = ROOT / "examples" / "fusiform_pulse.toml"
    assert main(["run", str(scene_file), "--out", str(tmp_path / "a"), "--no-preview", "-O", "max_iterations=1",
                 "-O", "accuracy=none", "-O", "alpha=100"]) == 1   # one iteration: not converged, exit 1
    log = json.loads((tmp_path / "a" / "log.json").read_text())
    assert log["frames"][1]["iterations"] <= 1
    assert main(["run", str(scene_file), "--out", str(tmp_path / "b"), "-O", "lagged_factor=true"]) == 2
    assert "lagged_factor is an option of FEM only" in capsys.readouterr().err


@pytest.mark.parametrize("group, kw, message", [
    ("StoppingOptions", {"rtol_grad": "x"}, "StoppingOptions: rtol_grad takes float, got 'x'"),
    ("StoppingOptions", {"max_iterations": 2.5}, "max_iterations takes int or None, got 2.5"),
    ("StoppingOptions", {"max_iterations": True}, "max_iterations takes int or None, got True"),
])
def test_an_option_group_checks_its_values_when_built(group, kw, message):
    """A wrong type fails where the group is made, not first in a Solver; an
    int serves a float option, None an optional one."""
    cls = getattr(emu, group)
    with pytest.raises(TypeError, match=message.replace("(", r"\(").replace(")", r"\)")):
        cls(**kw)
    assert cls(rtol_grad=1).given() == {"rtol_grad": 1}
    cls(max_iterations=None)   # the table's None-able options take None
