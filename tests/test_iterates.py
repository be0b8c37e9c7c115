"""Per-iteration records: every iterate's positions from either solver (an
on_iteration callback that can stop the solve, or recorded iterates), and the
error-against-time curve built from them."""
from __future__ import annotations

import numpy as np
import pytest

import emu
from emu.build.scenes import arm

from conftest import small_scene


@pytest.fixture(scope="module")
def scene():
    s, _ = small_scene(2)
    return s


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_recorded_iterates_are_the_solver_path(scene, method):
    kw = {"alpha": 100.0} if method == "emu" else {}   # one solve (accuracy mode may re-solve)
    sol = emu.solve(scene, {"belly": 5e4}, method, record_iterates=True, **kw)
    assert sol.converged, sol.status
    assert len(sol.iterates) == sol.iterations + 1
    times = [t for t, _ in sol.iterates]
    np.testing.assert_array_equal(times, sol.history["time_s"])
    tol = 1e-12 * np.abs(scene.points).max()
    np.testing.assert_allclose(sol.iterates[0][1], scene.points, rtol=0, atol=tol)   # the start: rest (EMU: its fit)
    np.testing.assert_allclose(sol.iterates[-1][1], sol.positions, rtol=0, atol=tol)
    # they move: each iterate is the solver's state, not a copy of the last
    steps = [np.abs(b - a).max() for (_, a), (_, b) in zip(sol.iterates, sol.iterates[1:])]
    assert min(steps[:3]) > 0


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_on_iteration_can_stop_the_solve(scene, method):
    seen = []

    def stop_at_two(record, positions):
        assert positions.shape == scene.points.shape and np.all(np.isfinite(positions))
        seen.append(record["iteration"])
        return record["iteration"] == 2

    sol = emu.solve(scene, {"belly": 5e4}, method, on_iteration=stop_at_two)
    assert seen == [0, 1, 2]
    assert not sol.converged and sol.status == "stopped by on_iteration" and sol.iterations == 2
    assert np.all(np.isfinite(sol.positions))


def test_on_iteration_exceptions_propagate_and_the_solver_stays_usable(scene):
    solver = emu.Solver(scene, "emu")

    def boom(record, positions):
        if record["iteration"] == 1:
            raise RuntimeError("from the callback")

    with pytest.raises(RuntimeError, match="from the callback"):
        solver.solve({"belly": 5e4}, on_iteration=boom)
    sol = solver.solve({"belly": 5e4})      # no callback left behind
    assert sol.converged and sol.iterates is None
    with pytest.raises(TypeError, match="callable"):
        solver.solve({"belly": 5e4}, on_iteration=3)


def test_bones_iterates_and_error_against_time():
    s = arm(1)
    fem = emu.solve(s, {"flexor": 0.4}, "fem", normalized=True, rtol_grad=1e-9)
    assert fem.converged
    sol = emu.solve(s, {"flexor": 0.4}, "emu", normalized=True, record_iterates=True, alpha=1e3)
    t, e = emu.error_history(sol, fem)
    assert len(t) == sol.iterations + 1 and np.all(np.diff(t) >= 0)
    assert e[0] > 10 * e[-1]                     # the forearm turned toward FEM's answer
    assert e[-1] == pytest.approx(emu.vertex_error(sol, fem))
    t1 = emu.time_to_error(sol, fem, 2 * e[-1])
    assert t[0] <= t1 <= t[-1]
    assert emu.time_to_error(sol, fem, 0.5 * e[-1]) == float("inf")   # never that close: EMU's own error
    with pytest.raises(ValueError, match="record_iterates"):
        emu.error_history(fem, fem)
