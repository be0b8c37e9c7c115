"""Inverted-tet counts: emu.inverted_tets on known configurations, and
Solution.inverted_tets / the frame log on solves that do and do not invert."""
from __future__ import annotations

import json

import numpy as np
import pytest

import emu
from conftest import SMALL_KINDS

TET = np.array([[0, 1, 2, 3]])
REST = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])


def test_inverted_tets_finds_reflected_and_flat_tets():
    assert len(emu.inverted_tets(TET, REST)) == 0
    mirrored = REST * [1, 1, -1]                  # reflected through z = 0: det F = -1
    assert emu.inverted_tets(TET, mirrored).tolist() == [0]
    flat = REST.copy()
    flat[3] = [0.3, 0.3, 0.0]                     # collapsed into a plane: det F = 0
    assert emu.inverted_tets(TET, flat).tolist() == [0]
    two = np.array([[0, 1, 2, 3], [0, 2, 1, 3]])  # the second one wrongly oriented at rest
    assert emu.inverted_tets(two, REST).tolist() == [1]


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_solutions_count_inverted_tets(method):
    make, act, normalized = SMALL_KINDS["fusiform (pinned, tendons)"]
    scene = make()
    solver = emu.Solver(scene, method, **({"alpha": 100, "error_estimate": False} if method == "emu" else {}))
    sol = solver.solve(act, normalized=normalized)
    assert sol.inverted_tets == 0 and "inverted" not in sol.summary()
    # The pinned end face collapsed to its centre: every tet with three or four
    # pinned vertices has zero volume whatever the solver does (Stable
    # Neo-Hookean stays finite there).
    pins = scene.points[scene.pinned]
    collapsed = np.repeat(pins.mean(axis=0)[None], len(pins), axis=0)
    flipped = solver.solve(act, normalized=normalized, pin_positions=collapsed)
    assert np.all(np.isfinite(flipped.positions))
    on_face = int((np.isin(scene.tets, scene.pinned).sum(axis=1) >= 3).sum())
    assert on_face > 0 and flipped.inverted_tets >= on_face
    assert flipped.inverted_tets == len(emu.inverted_tets(scene.tets, flipped.positions))
    assert f"{flipped.inverted_tets} inverted tet(s)" in flipped.summary()
