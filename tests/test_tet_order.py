"""The solvers store a scene's tets along a Z-order curve (the core's along_curve,
cpp/emu/model/tet_order.h; docs/DESIGN.md, "Tet order and the fit's per-vertex
sums"): an internal order that no answer depends on. The model Python builds lists the tets in the scene's order."""
import copy

import numpy as np
import pytest

import emu
from emu._core import FemSolver, SolverOptions
from emu.model.lowering import build_model


def with_tets_permuted(scene, perm):
    """The same scene with its tets listed in the order perm (new tet i = old tet perm[i])."""
    s = copy.deepcopy(scene)
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(perm))
    s.tets = scene.tets[perm]
    s._owner = scene._owner[perm]
    for p in s.parts.values():
        p.tets = inverse[p.tets]   # a part's fibres stay aligned with its list of tets
    return s


def solver_tet_order(scene):
    """The scene's tet of each tet as a solver stores them."""
    return np.asarray(FemSolver(build_model(scene), SolverOptions()).model.scene_tet)


def test_order_is_a_permutation_of_the_model_tets_and_local():
    s = emu.scenes.arm(2)
    order = solver_tet_order(s)
    np.testing.assert_array_equal(np.sort(order), np.sort(s.model_tets))
    shuffled = with_tets_permuted(s, np.random.default_rng(1).permutation(len(s.tets)))
    c = shuffled.points[shuffled.tets].mean(axis=1)
    given = np.linalg.norm(np.diff(c[shuffled.model_tets], axis=0), axis=1).mean()
    ordered = np.linalg.norm(np.diff(c[solver_tet_order(shuffled)], axis=0), axis=1).mean()
    assert ordered < 0.3 * given   # consecutive tets are neighbours, not random ones
    # the model Python builds: the scene's order; the solver's: every per-tet array carried along
    model = build_model(shuffled)
    np.testing.assert_array_equal(np.asarray(model.tets), shuffled.tets[shuffled.model_tets])
    np.testing.assert_array_equal(np.asarray(model.scene_tet), shuffled.model_tets)
    stored = FemSolver(model, SolverOptions()).model
    order = np.asarray(stored.scene_tet)
    np.testing.assert_array_equal(np.asarray(stored.tets), shuffled.tets[order])
    position = np.searchsorted(shuffled.model_tets, order)   # model tet of each stored tet
    for name in ("mu", "lam", "acap_weight", "muscle", "bone", "fiber"):
        np.testing.assert_array_equal(np.asarray(getattr(stored, name)), np.asarray(getattr(model, name))[position])
    assert stored.num_scene_tets == len(shuffled.tets)


def test_scene_tet_is_checked():
    s = emu.scenes.arm(1)
    model = build_model(s)
    bad = np.asarray(model.scene_tet).copy()
    bad[1] = bad[0]
    model.scene_tet = bad
    with pytest.raises(ValueError, match="scene_tet must name distinct scene tets"):
        FemSolver(model, SolverOptions())
    model = build_model(s)
    model.num_scene_tets = 3
    with pytest.raises(ValueError, match="num_scene_tets must be 0"):
        FemSolver(model, SolverOptions())


def test_answers_do_not_depend_on_the_order_of_the_tets():
    """A scene and the same scene with its tets shuffled: FEM's positions, EMU's
    positions and EMU's per-tet F (returned in the scene's order) agree, and a
    warm start from one solves the other at once."""
    s = emu.scenes.arm(1)
    perm = np.random.default_rng(2).permutation(len(s.tets))
    t = with_tets_permuted(s, perm)
    act = {"flexor": 0.4}
    for method in ("fem", "emu"):
        a = emu.Solver(s, method, **({"alpha": 300} if method == "emu" else {})).solve(act, normalized=True)
        b = emu.Solver(t, method, **({"alpha": 300} if method == "emu" else {})).solve(act, normalized=True)
        assert a.converged and b.converged
        assert emu.vertex_error(a, b) < 1e-6
        if method == "emu":
            np.testing.assert_allclose(b.F, a.F[perm], atol=1e-5)
            again = emu.Solver(t, "emu", alpha=300).solve(act, normalized=True, initial=a.F[perm])
            assert again.iterations <= 1 and emu.vertex_error(again, a) < 1e-6
