"""EMU's error estimate (Solution.error_estimate): the linearised FEM correction
at EMU's positions, against the true vertex error to the converged FEM answer
on small scenes over two decades of alpha (the full table over the shipped
scenes is bench/studies/error_estimate.py, quoted in docs/DESIGN.md)."""
from __future__ import annotations

import numpy as np
import pytest

import emu
from emu._core import testing
from emu.build.scenes import arm, fusiform, neck

from conftest import bone_chain_scene, bone_loop_scene


@pytest.mark.parametrize("alpha", [10.0, 100.0, 1000.0])
def test_estimate_is_within_a_factor_two_of_the_true_error(scene_with_fem, alpha):
    scene, act, normalized, fem = scene_with_fem
    sol = emu.Solver(scene, "emu", alpha=alpha).solve(act, normalized=normalized)
    assert sol.converged, sol.status
    true = emu.vertex_error(sol, fem)
    assert true > 1e-5          # EMU differs from FEM: there is an error to estimate
    assert sol.error_estimate is not None, sol.error_estimate_note
    assert 0.5 <= sol.error_estimate / true <= 2.0, (sol.error_estimate, true)
    assert sol.error_estimate_time_s > 0
    assert "estimated error to FEM" in sol.summary()


def test_estimate_follows_the_error_down_as_alpha_grows(scene_with_fem):
    scene, act, normalized, fem = scene_with_fem
    est = [emu.Solver(scene, "emu", alpha=a).solve(act, normalized=normalized).error_estimate for a in (10, 1000)]
    assert est[1] < 0.5 * est[0]


@pytest.mark.parametrize("make, act", [(lambda: neck(1), {"left_front": 0.5}), (lambda: arm(2), {"flexor": 0.4})])
def test_error_keeps_falling_as_one_over_alpha_at_large_alpha_on_bone_scenes(make, act):
    # The envelope's gap to FEM falls as 1/alpha. A gradient floor that summed
    # the bones' coupling moduli (ACAP weight 1e4) stopped EMU at alpha = 1e5 mu
    # as "converged" at |g|/|g0| = 3e-3: the neck's error was 1.22e-4 there
    # against 1.53e-4 at 1e4 mu.
    scene = make()
    fem = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=True)
    err = {}
    for alpha in (1e4, 1e5):
        sol = emu.Solver(scene, "emu", alpha=alpha).solve(act, normalized=True)
        assert sol.converged, sol.status
        err[alpha] = emu.vertex_error(sol, fem)
        assert 0.5 <= sol.error_estimate / err[alpha] <= 2.0
    assert err[1e5] < 0.2 * err[1e4], err


def test_no_estimate_for_fem_or_when_switched_off():
    s = fusiform(2, warn=False)
    assert emu.solve(s, {"belly": 5e4}, "fem").error_estimate is None
    off = emu.solve(s, {"belly": 5e4}, "emu", error_estimate=False)   # and so no default accuracy either
    assert off.error_estimate is None and off.error_estimate_time_s == 0.0
    assert off.settings["accuracy"] is None


def test_no_estimate_where_fem_cannot_solve_the_scene_says_why():
    s = bone_loop_scene()   # a closed loop of joints: EMU at a given alpha only (accuracy mode refuses it)
    sol = emu.Solver(s, "emu", alpha=100.0).solve({"m": 0.2}, normalized=True)
    assert sol.converged and sol.error_estimate is None
    assert "loop of joints" in sol.error_estimate_note


def test_estimate_on_a_chain_of_bones():
    """FEM solves chains, so EMU on one has its estimate, within [0.5, 2] of the true error."""
    s = bone_chain_scene()
    act = {"m1": 0.2, "m2": 0.2}
    sol = emu.Solver(s, "emu", alpha=30.0).solve(act, normalized=True)
    fem = emu.Solver(s, "fem", rtol_grad=1e-9).solve(act, normalized=True)
    true = np.abs(sol.positions - fem.positions).max() / np.linalg.norm(np.ptp(s.points, axis=0))
    assert sol.converged and true > 1e-4, (sol.status, true)
    assert 0.5 <= sol.error_estimate / true <= 2, (sol.error_estimate, true)


def test_correction_hessian_choices():
    """The estimate's step is the lower-energy one of the exact and filtered
    Newton steps: its FEM energy is at most either's."""
    s = fusiform(2, warn=False)
    fs = emu.Solver(s, "fem")
    load = fs.load_case({"belly": 5e4})
    x = emu.solve(s, {"belly": 5e4}, "emu", alpha=100.0).positions
    E = {h: testing.energy(fs._core, load, fs._core.newton_correction(load, x, h)) for h in ("exact", "filtered", "lower-energy")}
    assert E["lower-energy"] == min(E["exact"], E["filtered"])
    assert E["lower-energy"] < testing.energy(fs._core, load, x)
    with pytest.raises(ValueError, match="hessian must be"):
        fs._core.newton_correction(load, x, "dense")


def test_a_correction_where_pcg_meets_negative_curvature_skips_the_exact_factorisation():
    """The estimate's FEM corrections run PCG on a lagged factor first. Where
    that PCG meets p^T H p <= 0 the exact Newton matrix is indefinite, so its
    factorisation (which would fail) is not tried: the step is the filtered
    one, on the lagged factor where PCG reaches it, and equals a freshly
    factorised filtered step to PCG's tolerance."""
    s = fusiform(2, warn=False)
    act = {"belly": 5e4}
    solver = emu.Solver(s, "emu", alpha=100.0)
    solver.solve(act)   # the estimate's correction leaves a factor to lag on
    est = solver._estimator.fem
    load = solver.load_case(act)
    x = emu.solve(s, act, "emu", alpha=3.0, error_estimate=False).positions
    fresh = emu.Solver(s, "fem")._core
    _, H = testing.reduced_system(fresh, load, x, True)
    assert np.linalg.eigvalsh(H)[0] < 0   # the exact matrix at x is indefinite
    before = est.factorizations
    y = est.newton_correction(load, x, max_steps=1)
    assert est.factorizations - before <= 1   # not the failing exact attempt and then the filtered one
    y_ref = fresh.newton_correction(load, x, "filtered", max_steps=1)
    assert emu.vertex_error(y, y_ref) < 5e-2 * emu.vertex_error(x, y_ref)   # (PCG to 1e-3 |g|)


def test_a_correction_at_an_equilibrium_factorises_nothing():
    """Where FEM's own solve would stop at once (its gradient at round-off),
    the correction is no step: the positions come back unchanged and nothing
    is factorised. A sequence's first frame at rest then costs no
    factorisation; a loaded muscle still gets its Newton step."""
    s = fusiform(2, warn=False)
    fs = emu.Solver(s, "fem")._core
    rest = emu.Solver(s, "fem").load_case({"belly": 0.0})
    y = np.asarray(fs.newton_correction(rest, s.points, max_steps=2))
    assert np.array_equal(y, s.points) and fs.factorizations == 0
    loaded = emu.Solver(s, "fem").load_case({"belly": 5e4})
    y = np.asarray(fs.newton_correction(loaded, s.points, max_steps=1))
    assert fs.factorizations >= 1 and emu.vertex_error(y, s.points) > 1e-3
    # in accuracy mode: the first frame at rest has a zero estimate and leaves no factor
    solver = emu.Solver(s, "emu", accuracy=0.01)
    sol = solver.solve({"belly": 0.0})
    assert sol.error_estimate < 1e-12 and solver._estimator.fem.factorizations == 0
