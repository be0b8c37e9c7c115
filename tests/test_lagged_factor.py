"""FEM Newton-CG on a lagged Cholesky factor (Solver(method="fem",
lagged_factor=True)): the same equilibrium as Newton with a factorisation per
iteration, far fewer factorisations, the factor reused across the solves of a
sequence."""
from __future__ import annotations

import numpy as np
import pytest

import emu
from conftest import SMALL_KINDS


@pytest.fixture(scope="module", params=list(SMALL_KINDS))
def kind(request):
    make, act, normalized = SMALL_KINDS[request.param]
    return make(), act, normalized


def test_lagged_factor_reaches_the_direct_answer_with_fewer_factorizations(kind):
    scene, act, normalized = kind
    direct = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
    lagged = emu.Solver(scene, "fem", rtol_grad=1e-9, lagged_factor=True).solve(act, normalized=normalized)
    assert direct.converged and lagged.converged, (direct.status, lagged.status)
    assert emu.vertex_error(lagged.positions, direct.positions) < 1e-7
    assert direct.cg_iterations == 0 and direct.factorizations >= direct.iterations
    assert lagged.cg_iterations > 0
    assert lagged.factorizations <= direct.factorizations / 2
    assert lagged.label == "fem_lagged_cg" and direct.label == "fem"


def test_lagged_factor_is_reused_across_the_frames_of_a_sequence(kind):
    # A small change of activation, warm-started: the factor from the first
    # solve preconditions the second without a new factorisation.
    scene, act, normalized = kind
    solver = emu.Solver(scene, "fem", lagged_factor=True)
    first = solver.solve(act, normalized=normalized)
    nudged = {m: 1.02 * a for m, a in act.items()}
    second = solver.solve(nudged, normalized=normalized, initial=first)
    direct = emu.Solver(scene, "fem").solve(nudged, normalized=normalized, initial=first)
    assert first.factorizations >= 1
    assert second.converged and second.factorizations == 0 and second.cg_iterations > 0
    assert emu.vertex_error(second.positions, direct.positions) < 1e-5


def test_an_aged_factor_is_refreshed_before_its_pcg_grows():
    # A sequence of growing activations: PCG on the first frame's factor grows
    # frame by frame. With lagged_refresh a solve past refresh_iterations makes
    # the next step factorise: more factorisations, fewer PCG iterations, the
    # same answers.
    scene = emu.scenes.fusiform(3, warn=False)
    runs = {}
    for refresh in (False, True):
        solver = emu.Solver(scene, "fem", lagged_factor=True, lagged_refresh=refresh, rtol_grad=1e-9)
        prev, answers = None, []
        for a in np.linspace(1e4, 1e5, 6):
            prev = solver.solve({"belly": a}, initial=prev)
            assert prev.converged, prev.status
            answers.append(prev.positions)
        assert solver.settings["lagged_refresh"] is refresh
        runs[refresh] = (solver._core, answers)
    (plain, plain_x), (fresh, fresh_x) = runs[False], runs[True]
    assert fresh.refresh_iterations >= 8
    assert fresh.factorizations > plain.factorizations
    assert fresh.pcg_iterations < 0.75 * plain.pcg_iterations
    for a, b in zip(plain_x, fresh_x):
        assert emu.vertex_error(a, b) < 1e-7


def test_a_one_iteration_cap_still_converges_by_factorising():
    # PCG capped at one iteration cannot reach the forcing term on the first
    # steps: those steps factorise, and the answer is the direct one.
    make, act, normalized = SMALL_KINDS["fusiform (pinned, tendons)"]
    scene = make()
    direct = emu.Solver(scene, "fem").solve(act, normalized=normalized)
    capped = emu.Solver(scene, "fem", lagged_factor=True, lagged_cg_iterations=1).solve(act, normalized=normalized)
    assert capped.converged
    assert capped.factorizations > 1
    assert emu.vertex_error(capped.positions, direct.positions) < 1e-5


def test_lagged_factor_options_are_checked():
    make, _, _ = SMALL_KINDS["fusiform (pinned, tendons)"]
    scene = make()
    with pytest.raises(ValueError, match="lagged_factor is an option of FEM only"):
        emu.Solver(scene, "emu", lagged_factor=True)
    with pytest.raises(ValueError, match="lagged_cg_iterations must be >= 1"):
        emu.Solver(scene, "fem", lagged_factor=True, lagged_cg_iterations=0)


def test_phase_times_account_for_the_solve(kind):
    scene, act, normalized = kind
    for method in ("fem", "emu"):
        sol = emu.Solver(scene, method, **({"alpha": 100, "error_estimate": False} if method == "emu" else {})).solve(act, normalized=normalized)
        t = sol.phase_times
        assert set(t) == {"hessian", "preconditioner", "linear_solve", "line_search", "step", "error_estimate",
                          "other"}
        assert t["error_estimate"] == 0   # none asked for
        assert all(v >= 0 for v in t.values())
        assert sum(t.values()) == pytest.approx(sol.time_s, rel=1e-6, abs=1e-9)
        assert t["linear_solve"] > 0 and t["hessian"] > 0
        if method == "fem":
            assert t["preconditioner"] == 0


def test_error_estimate_on_the_lagged_factor_matches_a_fresh_factorisation(kind):
    # The second solve's estimate reuses the first's factor (PCG to 1e-3 |g|);
    # a new solver estimates the same state with a factorisation of its own.
    scene, act, normalized = kind
    solver = emu.Solver(scene, "emu", alpha=100)
    first = solver.solve(act, normalized=normalized)
    nudged = {m: 1.05 * a for m, a in act.items()}
    second = solver.solve(nudged, normalized=normalized, initial=first)
    fresh = emu.Solver(scene, "emu", alpha=100)
    x1, _, note = fresh._estimator.first_correction(fresh.load_case(nudged, normalized), second.positions)
    fresh_estimate = emu.vertex_error(second.positions, x1)
    assert note == "" and second.error_estimate is not None
    assert emu.vertex_error(second.positions, second.fem_correction) == pytest.approx(fresh_estimate, rel=1e-2)


def test_factorizations_are_counted_for_emu_schur_rebuilds_only():
    make, act, normalized = SMALL_KINDS["fusiform (pinned, tendons)"]
    scene = make()
    woodbury = emu.Solver(scene, "emu", alpha=100, error_estimate=False).solve(act, normalized=normalized)
    schur = emu.Solver(scene, "emu", alpha=100, error_estimate=False, preconditioner="schur",
                       preconditioner_refresh=2).solve(act, normalized=normalized)
    assert woodbury.factorizations == 0
    # rebuilt at the first step and at least every second one after
    assert schur.factorizations >= (schur.iterations + 1) // 2
