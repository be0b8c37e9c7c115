"""The solver's options are written once (emu.options.OPTIONS): the Solver's
signature, the scene-file schema and the docs' options page come from it; an
unknown option names the nearest one, and an option of the other method (or
of another EMU step) is an error naming it."""
import inspect
from pathlib import Path

import pytest

import emu
from emu.app.scenefile import _SCHEMA
from emu.options import OPTIONS, options_markdown

ROOT = Path(__file__).resolve().parents[1]


def test_the_signature_and_the_scene_file_schema_come_from_the_table():
    params = inspect.signature(emu.Solver).parameters
    assert [p for p in params if p not in ("scene", "method")] == list(OPTIONS)
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
    from emu.scenefile import SceneFileError, load_scene_file
    from test_scenefile import GOOD

    (tmp_path / "s.toml").write_text(GOOD.replace("alpha = 100.0", "alpha = 100.0\nlagged_factor = true"))
    with pytest.raises(SceneFileError, match="solver.lagged_factor is an option of FEM only"):
        load_scene_file(tmp_path / "s.toml")
    (tmp_path / "t.toml").write_text(GOOD.replace("alpha = 100.0", "alpha = \"high\""))
    with pytest.raises(SceneFileError, match="solver.alpha"):
        load_scene_file(tmp_path / "t.toml")
