"""Stiff and extreme cases on both solvers (the cases of bench/stability.py,
whose table is docs/stability.md): each ends with finite positions, an
energy no higher than at the start and its inverted tets counted, converged
or stopped with a status that says why; never NaN, a crash or a hang (every
solve is capped). Run alone with ``pytest -m stress``."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import emu

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from stability import CASES, run_case  # noqa: E402

pytestmark = pytest.mark.stress

# (method, label, scene options, activation, EMU options); EMU-only settings only for EMU
CASE_LIST = [(method, label, scene_kw, act, emu_kw)
             for cases in CASES.values() for label, scene_kw, act, emu_kw in cases
             for method in ("fem", "emu") if method == "emu" or not emu_kw]


@pytest.mark.parametrize("method,label,scene_kw,activation,emu_kw", CASE_LIST,
                         ids=[f"{c[0]}: {c[1]}" for c in CASE_LIST])
def test_extreme_case_ends_in_a_physical_state(method, label, scene_kw, activation, emu_kw):
    scene, sol, _ = run_case(method, scene_kw, activation, emu_kw, max_iterations=300)
    assert np.all(np.isfinite(sol.positions)), label
    energies = np.asarray(sol.history["energy"])
    assert np.all(np.isfinite(energies)) and energies[-1] <= energies[0] + 1e-12 * abs(energies[0]), label
    assert sol.inverted_tets == len(emu.inverted_tets(scene.tets, sol.positions))
    # the pinned vertices stayed where they were put
    assert np.allclose(sol.positions[scene.pinned], scene.points[scene.pinned], atol=1e-12 * np.ptp(scene.points))
    if not sol.converged:
        assert sol.status and sol.status != "converged", label
    if method == "emu" and sol.error_estimate is not None:
        assert np.isfinite(sol.error_estimate) and sol.error_estimate >= 0
