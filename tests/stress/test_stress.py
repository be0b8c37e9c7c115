"""Stiff and extreme cases on both solvers (the cases of bench/stability.py,
whose table is docs/stability.md): each frame ends with finite positions, an
energy no higher than at its start, the pins held, fixed bones at rest,
movable bones rigid and its inverted tets counted, converged or stopped with a
status that says why; a scene a method cannot take is refused with a
ValueError naming the problem. Never NaN, a crash or a hang (every solve is
capped). Run alone with ``pytest -m stress``."""
from __future__ import annotations

import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import emu
from emu._core import testing

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from stability import (CASES, arm, bar, every_other_flipped, inverted_bar, pinned_bar,  # noqa: E402
                       pinned_muscle, run_case)

pytestmark = pytest.mark.stress

CASE_LIST = [(method, case) for cases in CASES.values() for case in cases for method in case.methods()]


def bone_rigidity_tolerance(scene, part, method):
    """FEM's bones are rigid bodies; EMU's follow a rigid motion through their
    ACAP weight w, to about 3e-3 / w of their diagonal (measured: 3e-7 at the
    default 1e4, 3e-5 at 100): allow 0.1 / w."""
    return 1e-12 if method == "fem" else 0.1 / part.acap_weight


def assert_physical(scene, sol, method, label):
    assert np.all(np.isfinite(sol.positions)), label
    energies = np.asarray(sol.history["energy"])
    assert np.all(np.isfinite(energies)), label
    # one block per solve of the frame (accuracy mode's re-solves at another alpha: another energy)
    starts = np.flatnonzero(np.asarray(sol.history["iteration"]) == 0).tolist() + [len(energies)]
    for a, b in zip(starts, starts[1:]):
        assert energies[b - 1] <= energies[a] + 1e-12 * abs(energies[a]), (label, a)
    assert sol.inverted_tets == len(emu.inverted_tets(scene.tets, sol.positions))
    diag = np.ptp(scene.points, axis=0).max()
    assert np.allclose(sol.positions[scene.pinned], scene.points[scene.pinned], atol=1e-12 * diag), label
    for part in scene.parts.values():
        if part.kind != "bone":
            continue
        v = np.unique(scene.tets[part.tets])
        if part.fixed:
            assert np.allclose(sol.positions[v], scene.points[v], atol=1e-12 * diag), (label, part.name)
        else:
            rigidity = emu.bone_motion(scene, sol, part.name).rigidity
            assert rigidity <= bone_rigidity_tolerance(scene, part, method), (label, part.name, rigidity)
    if not sol.converged:
        assert sol.status and sol.status != "converged", label
    if sol.error_estimate is not None:
        assert np.isfinite(sol.error_estimate) and sol.error_estimate >= 0
        if sol.accuracy_reached is False:
            assert "not reached" in sol.error_estimate_note, label


@pytest.mark.parametrize("method,case", CASE_LIST, ids=[f"{m}: {c.label}" for m, c in CASE_LIST])
def test_extreme_case_ends_in_a_physical_state(method, case):
    out = run_case(method, case, max_iterations=300)
    refusal = case.refusal(method)
    if refusal is not None:
        assert re.search(refusal, out.refused), (case.label, out.refused)
        return
    assert len(out.solutions) == case.frames
    for sol in out.solutions:
        assert_physical(out.scene, sol, method, case.label)


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_bone_stiffness_does_not_change_rigid_bones(method):
    """Bones are rigid: their Young's modulus (1e3 or 1e8 times the muscles')
    must not change the answer."""
    x = [emu.Solver(arm(bone_ratio=r), method).solve({"flexor": 1e6}).positions for r in (1e3, 1e8)]
    np.testing.assert_array_equal(x[0], x[1])


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_inverted_rest_tets_solve_as_the_oriented_mesh(method):
    """Rest tets given with negative volume are reoriented (with a MeshWarning)
    and the solve is the one of the mesh given the right way round."""
    points, tets = bar()
    flipped = every_other_flipped(tets)
    with pytest.warns(emu.MeshWarning, match=f"{len(tets[::2])} tet\\(s\\) had negative volume"):
        emu.Scene(points, flipped)
    a = emu.Solver(inverted_bar(), method).solve({"belly": 1e5}).positions
    b = emu.Solver(pinned_bar(*bar()), method).solve({"belly": 1e5}).positions
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.ptp(b))


def test_accuracy_not_reached_is_reported():
    """Far past the activations that invert tets (1e10 and 1e12 on a muscle
    whose maximum is 1e5) EMU and FEM find different inverted equilibria and
    raising alpha does not close the gap. At 1e10 FEM's corrections of EMU's
    answer converge; without them the solution says the accuracy was not
    reached, with a warning, instead of passing the answer off as within 1%.
    EMU's estimate there does not certify itself, and accuracy mode's default
    settles the answer by a FEM solve from it (at 1e10 and at 1e12)."""
    s = pinned_muscle()
    with pytest.warns(emu.AccuracyWarning, match="not reached"):
        resolved = emu.Solver(s, "emu", fem_correction=False).solve({"belly": 1e10})
    assert resolved.accuracy_reached is False and resolved.error_estimate > 0.01
    assert "not reached" in resolved.summary()
    fem = emu.Solver(s, "fem").solve({"belly": 1e10})
    assert emu.vertex_error(resolved, fem) > 0.01   # the warning was due
    # EMU's estimate there does not certify itself (its FEM Newton steps do not
    # contract): the answer is settled by a FEM solve, and the user is told once
    with pytest.warns(emu.AccuracyWarning, match="could not certify itself"):
        corrected = emu.Solver(s, "emu").solve({"belly": 1e10})
    assert corrected.corrected and corrected.accuracy_reached is True
    assert corrected.error_estimate_certified is False and "settled by a FEM solve" in corrected.error_estimate_note
    assert emu.vertex_error(corrected, fem) <= 0.01
    # at 1e12 FEM's Newton corrections alone do not converge, but a FEM solve
    # from EMU's answer reaches FEM's own (inverted) equilibrium
    with pytest.warns(emu.AccuracyWarning, match="could not certify itself"):
        far = emu.Solver(s, "emu").solve({"belly": 1e12})
    assert far.accuracy_reached is True and far.corrected
    assert emu.vertex_error(far, emu.Solver(s, "fem").solve({"belly": 1e12})) <= 0.01
    with warnings.catch_warnings():
        warnings.simplefilter("error", emu.AccuracyWarning)
        ok = emu.Solver(s, "emu").solve({"belly": 5e4})
    assert ok.accuracy_reached is True


def test_fem_leaves_a_saddle_along_negative_curvature():
    """At Poisson 0.4999 the contracted muscle buckles: the symmetric shape is a
    saddle, and FEM's filtered Newton steps stay on it: depending on round-off
    (the tets' order) they wander there past 150 steps or pass the gradient
    test on the saddle itself (114 steps, |g| / |g0| = 9e-7). With the
    negative-curvature step (the default) FEM converges in under 100 to a local
    minimum: the exact Hessian of the reduced unknowns there is positive
    definite (a dense eigen-solve), and the energy is below the saddle's."""
    s = pinned_muscle(poisson=0.4999)
    act = {"belly": 5e4}
    slow = emu.Solver(s, "fem", max_iterations=150, negative_curvature=False).solve(act)
    assert slow.negative_curvature_steps == 0
    fast = emu.Solver(s, "fem", max_iterations=150).solve(act)
    assert fast.converged and fast.iterations < 100 and fast.negative_curvature_steps >= 1
    solver = emu.Solver(s, "fem")
    load = solver.load_case(act)
    _, H = testing.reduced_system(solver._core, load, fast.positions, True)
    assert np.linalg.eigvalsh(H)[0] > 0                      # a minimum, not a saddle
    # the saddle: where the slow run sat at iteration 100, |g| / |g0| ~ 1e-6
    # (whether it later converges there or starts to leave is round-off)
    saddle = np.asarray(slow.history["energy"])[100]
    assert fast.energy < saddle - 1e-3 * abs(saddle)
    _, Hs = testing.reduced_system(solver._core, load, emu.Solver(s, "fem", max_iterations=100, negative_curvature=False)
                                        .solve(act).positions, True)
    assert np.linalg.eigvalsh(Hs)[0] < 0                     # ... and it is one
