"""Newton-Krylov's preconditioners change CG's path, not EMU's answer: the
constant Schur complement (preconditioner='constant-schur') against the
paper's Woodbury approximation on every small scene kind, bones and joints
included, and its structures and refusals."""
from __future__ import annotations

import numpy as np
import pytest

import emu
from conftest import SMALL_KINDS, bone_chain_scene

KINDS = dict(SMALL_KINDS, **{"chain (two movable bones)": (bone_chain_scene, {"m1": 0.4, "m3": 0.4}, True)})


@pytest.mark.parametrize("kind", list(KINDS))
def test_constant_schur_reaches_the_woodbury_answer(kind):
    make, act, normalized = KINDS[kind]
    scene = make()
    diag = emu.bbox_diagonal(scene.points)
    sols = {}
    for pc in ("woodbury", "constant-schur"):
        solver = emu.Solver(scene, "emu", alpha=100, error_estimate=False, rtol_grad=1e-9, preconditioner=pc)
        sols[pc] = solver.solve(act, normalized=normalized)
        assert sols[pc].converged, (pc, sols[pc].status)
        assert sols[pc].cg_iterations > 0
    apart = np.abs(sols["woodbury"].positions - sols["constant-schur"].positions).max() / diag
    assert apart < 1e-6, apart


def test_constant_schur_builds_no_modes_and_survives_a_new_alpha():
    scene = emu.scenes.fusiform(2, warn=False)
    solver = emu.Solver(scene, "emu", alpha=100, error_estimate=False, preconditioner="constant-schur")
    built = solver.structures()
    assert "constant Schur preconditioner" in built and "ACAP modes" not in built
    assert "Woodbury block inverses" not in built
    a = solver.solve({"belly": 5e4})
    solver.set_alpha(1000)                       # S0's weights depend on alpha: refactorised
    b = solver.solve({"belly": 5e4}, initial=a)
    ref = emu.Solver(scene, "emu", alpha=1000, error_estimate=False).solve({"belly": 5e4})
    assert b.converged and np.abs(b.positions - ref.positions).max() < 1e-6 * emu.bbox_diagonal(scene.points)


def test_unknown_preconditioner_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="constant-schur"):
        emu.Solver(emu.scenes.fusiform(2, warn=False), "emu", preconditioner="jacobi")


@pytest.mark.parametrize("kind", list(KINDS))
def test_cg_truncation_test_changes_the_path_not_the_answer(kind):
    """CG's Nash-Sofer truncation test (cg_model_decrease, on by default) and
    the residual test alone reach the same strict answer."""
    make, act, normalized = KINDS[kind]
    scene = make()
    diag = emu.bbox_diagonal(scene.points)
    sols = {}
    for c in (0.0, 0.5):
        solver = emu.Solver(scene, "emu", alpha=100, error_estimate=False, rtol_grad=1e-9, cg_model_decrease=c)
        assert solver.settings["cg_model_decrease"] == c
        sols[c] = solver.solve(act, normalized=normalized)
        assert sols[c].converged, (c, sols[c].status)
    apart = np.abs(sols[0.0].positions - sols[0.5].positions).max() / diag
    assert apart < 1e-6, apart
    # ... and the option reaches CG: its path differs
    assert list(sols[0.0].history["cg_iterations"]) != list(sols[0.5].history["cg_iterations"])


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_cg_model_decrease_outside_zero_one_is_refused(bad):
    with pytest.raises(ValueError, match="cg_model_decrease must lie in"):
        emu.Solver(emu.scenes.fusiform(2, warn=False), "emu", alpha=100, cg_model_decrease=bad)
