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


@pytest.mark.parametrize("kind", list(SMALL_KINDS))
def test_accuracy_mode_floors_cg_forcing_where_its_step_test_applies(kind):
    """In accuracy mode CG's forcing term is floored at sqrt(STEP_GRAD) = 0.1
    (cg_forcing_min): the steps taken while |g| >= STEP_GRAD |g_0| (where
    Eisenstat-Walker's term is at least 0.1) are the same CG solves as without
    the floor, the first step it can act on stops no later (from the same
    state, a looser tolerance), and both answers are within the accuracy of
    FEM's."""
    from emu.solve.accuracy import ACCURACY_CG_FORCING_MIN, STEP_GRAD
    assert ACCURACY_CG_FORCING_MIN == pytest.approx(STEP_GRAD ** 0.5)
    make, act, normalized = SMALL_KINDS[kind]
    scene = make()
    fem = emu.solve(scene, act, "fem", normalized=normalized)
    sols = {}
    for floor in (0.0, None):
        solver = emu.Solver(scene, "emu", accuracy=0.01, alpha=100, cg_forcing_min=floor)
        assert solver.settings["cg_forcing_min"] == (0.0 if floor == 0.0 else ACCURACY_CG_FORCING_MIN)
        sols[floor] = sol = solver.solve(act, normalized=normalized)
        assert sol.converged and sol.accuracy_reached, (floor, sol.status)
        assert emu.vertex_error(sol.positions, fem.positions) < 0.01
    h0, h1 = sols[0.0].history, sols[None].history
    g = h0["grad_norm"]
    early = next((i for i in range(1, len(g)) if g[i - 1] < STEP_GRAD * g[0]), len(g))
    assert early > 1   # steps before the floor can act
    assert list(h0["cg_iterations"][:early]) == list(h1["cg_iterations"][:early])
    if early < len(g) and len(h1["cg_iterations"]) > early:   # the first step the floor may shorten
        assert h1["cg_iterations"][early] <= h0["cg_iterations"][early]
    if kind.startswith("arm"):   # its endgame goes below STEP_GRAD |g_0| in the first solve: the floor acts
        assert sols[None].cg_iterations < sols[0.0].cg_iterations


def test_strict_solves_have_no_cg_forcing_floor_and_bad_floors_are_refused():
    scene = emu.scenes.fusiform(2, warn=False)
    assert emu.Solver(scene, "emu", alpha=100, error_estimate=False).settings["cg_forcing_min"] == 0.0
    for bad in (-0.1, 1.0, float("nan"), True, "0.1"):
        with pytest.raises(ValueError, match="cg_forcing_min must lie in"):
            emu.Solver(scene, "emu", alpha=100, cg_forcing_min=bad)
    with pytest.raises(ValueError, match="cg_forcing_min is an option of EMU only; leave it out for method='fem'"):
        emu.Solver(scene, "fem", cg_forcing_min=0.1)
    for step in ("lbfgs", "woodbury"):
        with pytest.raises(ValueError, match=f"cg_forcing_min applies to EMU's newton-krylov step only; leave it "
                                             f"out for step='{step}'"):
            emu.Solver(scene, "emu", step=step, cg_forcing_min=0.1)
    opts = emu._core.EmuSolverOptions()
    opts.alpha, opts.cg_forcing_min = 1e5, float("nan")   # the core refuses it too
    with pytest.raises(ValueError, match="cg_forcing_min must lie in"):
        emu._core.EmuSolver(emu.Solver(scene, "emu", alpha=100).model, emu._core.SolverOptions(), opts)
