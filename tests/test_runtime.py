"""emu.runtime: the thread count a solve runs on. Automatic by default: every
core this process may use, fewer where other processes kept cores busy since
the last solve (measured from /proc/stat); a count the user chose is kept."""
from __future__ import annotations

import pytest

import emu
from emu import _core
from emu.core import runtime
from emu.core.runtime import _Sample, free_cores


@pytest.fixture
def auto(monkeypatch):
    """Automatic threads on a pretend machine of two cores whose samples the test gives."""
    samples = []
    monkeypatch.setattr(runtime, "_cpus", [0, 1])
    monkeypatch.setattr(runtime, "_default_threads", 2)
    monkeypatch.setattr(runtime, "_sample", lambda cpus: samples.pop(0))
    samples.append(_Sample(0.0, 0.0, 0.0))
    runtime.set_threads(None)
    yield samples
    monkeypatch.undo()
    runtime.set_threads(None)


def test_free_cores_is_the_cores_less_what_others_used():
    before = _Sample(busy_s=10.0, own_s=1.0, wall_s=100.0)
    # over 2 s the cores were busy 3.5 s, 1.5 s of it this process: others used 1 core
    assert free_cores(before, _Sample(13.5, 2.5, 102.0), 2) == pytest.approx(1.0)
    assert free_cores(before, _Sample(11.0, 2.0, 102.0), 2) == pytest.approx(2.0)    # only us
    assert free_cores(before, _Sample(10.01, 1.0, 100.01), 2) is None                # too short to tell
    assert free_cores(None, before, 2) is None


def test_a_solve_steps_down_where_other_processes_hold_the_cores(auto):
    s = emu.scenes.fusiform(1, warn=False)
    solver = emu.Solver(s, "fem", rtol_grad=1e-6)
    # other processes kept both cores busy for a second: one thread
    auto.append(_Sample(2.0, 0.0, 1.0))
    sol = solver.solve({"belly": 1e4})
    assert sol.converged and sol.settings["threads"] == 1 and _core.blas_info()["omp_threads"] == 1
    # a quiet second (only this process busy): every core again
    auto.append(_Sample(3.5, 1.5, 2.0))
    assert solver.solve({"belly": 1e4}).settings["threads"] == 2
    assert _core.blas_info()["omp_threads"] == 2
    # a stretch too short to measure keeps the count, and the stretch grows to the next solve
    auto.append(_Sample(3.51, 1.5, 2.01))
    assert runtime.adapt_threads() == 2
    auto.append(_Sample(5.5, 1.5, 3.0))      # since t = 2: others used 2 cores
    assert runtime.adapt_threads() == 1
    assert runtime.info()["threads"] == "auto (up to 2)"


def test_a_chosen_count_is_kept(auto):
    runtime.set_threads(1)
    assert runtime.adapt_threads() == 1 and runtime.info()["threads"] == "1"
    assert auto == []      # nothing sampled for a chosen count (a sample would come from this list)
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="threads must be an integer >= 1"):
            runtime.set_threads(bad)
