"""Stopping at round-off: EMU's strict solves also stop when a full step moves
no vertex by more than position_tol of the diagonal (once |g| <= 1e-3 |g_0|),
and both solvers when the gradient is within noise_factor of its measured
round-off (the measured floor itself: cpp/tests/solvers/newton/test_newton.cpp)."""
from __future__ import annotations

import math

import pytest

import emu
from emu.core.geometry import vertex_error

ACT = {"flexor": 0.4}
STEP_STATUS = "converged: a full step moved no vertex by more than step_tol"


@pytest.fixture(scope="module")
def arm():
    return emu.scenes.arm(1)


def test_position_tol_stops_within_its_distance_of_the_strict_answer(arm):
    strict = emu.Solver(arm, "emu", alpha=300, error_estimate=False, position_tol=0).solve(ACT, normalized=True)
    assert strict.converged and strict.status != STEP_STATUS
    # an unreachable gradient tolerance: only the step test can stop the solve early
    loose = emu.Solver(arm, "emu", alpha=300, error_estimate=False, rtol_grad=1e-14, noise_factor=0,
                       position_tol=1e-3).solve(ACT, normalized=True)
    assert loose.converged and loose.status == STEP_STATUS
    assert loose.iterations < strict.iterations
    assert loose.grad_norm <= 1e-3 * loose.grad_norm0           # the step test waits for the endgame
    # its last full step moved no vertex by more than 1e-3 of the diagonal, and
    # Newton-Krylov contracts at least by half per step: within 2e-3 of the answer
    assert 0 < vertex_error(loose, strict, arm.points) <= 2e-3
    assert loose.settings["position_tol"] == 1e-3


def test_position_tol_is_emu_newton_krylov_strict_only(arm):
    # FEM, EMU's accuracy mode and the slowly converging steps keep their own tests
    with pytest.raises(ValueError, match="position_tol is an option of EMU only"):
        emu.Solver(arm, "fem", rtol_grad=1e-14, position_tol=1e-3, noise_factor=0)
    with pytest.raises(ValueError, match="position_tol applies to EMU's newton-krylov step only"):
        emu.Solver(arm, "emu", alpha=300, step="woodbury", position_tol=1e-3)
    fem = emu.Solver(arm, "fem", rtol_grad=1e-14, noise_factor=0)
    assert fem.solve(ACT, normalized=True).status != STEP_STATUS
    for solver in (fem, emu.Solver(arm, "emu", accuracy=0.01, position_tol=1e-3)):
        assert solver.settings["position_tol"] is None   # not applied
    assert emu.Solver(arm, "emu", alpha=300).settings["position_tol"] == 1e-7


@pytest.mark.parametrize("kw", [dict(position_tol=-1e-8), dict(position_tol=1.0), dict(position_tol=math.nan),
                                dict(noise_factor=-1.0), dict(noise_factor=math.inf)])
def test_bad_roundoff_options_are_refused(arm, kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        emu.Solver(arm, "emu", alpha=300, **kw)
