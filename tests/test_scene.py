"""The scene and what is built from it: the lowering to the C++ model leaves the
scene alone, joints are Joint dataclasses, one bounding-box diagonal, the
built-in fusiform scene, poses."""
import copy

import numpy as np
import pytest

import emu
from emu.model.joints import Joint
from emu.core.geometry import tet_vertices
from emu.model.lowering import build_model, tet_fibers

from conftest import bone_muscle_bone, gap_scene


def snapshot(scene):
    """Everything a lowering could change, copied."""
    return {"points": scene.points.copy(), "tets": scene.tets.copy(), "pinned": scene.pinned.copy(),
            "pin_targets": scene.pin_targets.copy(), "gravity": np.array(scene.gravity, float),
            "parts": copy.deepcopy(scene.parts), "declared": copy.deepcopy(scene.declared_joints)}


def assert_unchanged(scene, before):
    for key in ("points", "tets", "pinned", "pin_targets", "gravity"):
        np.testing.assert_array_equal(getattr(scene, key) if key != "gravity" else scene.gravity, before[key])
    assert list(scene.parts) == list(before["parts"])
    for name, p in scene.parts.items():
        q = before["parts"][name]
        np.testing.assert_array_equal(p.tets, q.tets)
        assert (p.kind, p.youngs, p.poisson, p.density, p.fixed, p.max_activation, p.joint_stiffness) == \
            (q.kind, q.youngs, q.poisson, q.density, q.fixed, q.max_activation, q.joint_stiffness)
        assert np.array_equal(p.acap_weight, q.acap_weight, equal_nan=True)
        if q.fibers is None:
            assert p.fibers is None, f"the lowering wrote fibres into part '{name}'"
        else:
            np.testing.assert_array_equal(p.fibers, q.fibers)
    assert len(scene.declared_joints) == len(before["declared"])


def test_build_model_does_not_change_the_scene():
    """A muscle without fibres gets its Laplace field in the model, not in the
    scene; building twice gives the same model and leaves the scene as it was."""
    s, _, _ = bone_muscle_bone(0.15, r=2)
    assert s.parts["belly"].fibers is None
    before = snapshot(s)
    a = build_model(s)
    assert_unchanged(s, before)
    b = build_model(s)
    assert_unchanged(s, before)
    fa, fb = np.asarray(a.fiber), np.asarray(b.fiber)
    np.testing.assert_array_equal(fa, fb)
    np.testing.assert_allclose(np.linalg.norm(fa, axis=1), 1.0, atol=1e-12)   # the belly's Laplace field
    # the same field as resolving it into a copy of the scene
    c = copy.deepcopy(s)
    c.resolve_fibers()
    resolved = np.zeros((len(s.tets), 3))
    resolved[c.parts["belly"].tets] = c.parts["belly"].fibers
    np.testing.assert_array_equal(fa, resolved[s.model_tets])   # the model's tets: the scene's order
    np.testing.assert_array_equal(tet_fibers(s)[s.parts["belly"].tets], c.parts["belly"].fibers)


def test_solver_does_not_change_the_scene():
    s = gap_scene()
    s.add_joint("lower", "upper", centre=[1.5, 1.5, 0.5], axis=[0, 0, 1])
    s.gravity = [0.0, -9.81, 0.0]
    before = snapshot(s)
    for method in ("fem", "emu"):
        solver = emu.Solver(s, method)
        assert_unchanged(s, before)
        assert solver.fibers.shape == (len(s.tets), 3)
        np.testing.assert_allclose(np.linalg.norm(solver.fibers[s.parts["muscle"].tets], axis=1), 1.0, atol=1e-12)
        np.testing.assert_array_equal(solver.fibers[s.parts["upper"].tets], 0.0)
        sol = solver.solve({"muscle": 0.2}, normalized=True)
        assert sol.converged, sol.status
        assert_unchanged(s, before)


def test_given_fibres_pass_through_untouched():
    s = emu.scenes.fusiform(2)
    before = snapshot(s)
    model = build_model(s)
    assert_unchanged(s, before)
    np.testing.assert_array_equal(np.asarray(model.scene_tet), s.model_tets)
    np.testing.assert_array_equal(np.asarray(model.fiber), tet_fibers(s)[s.model_tets])
    np.testing.assert_array_equal(tet_fibers(s)[s.parts["belly"].tets], s.parts["belly"].fibers)
    with pytest.raises(ValueError, match=r"fibers must have shape"):
        build_model(s, fibers=np.zeros((3, 3)))


# ------------------------------------------------------------------ joints
def test_joints_are_dataclasses():
    arm = emu.scenes.arm(1)
    (j,) = arm.joints()
    assert isinstance(j, Joint) and not j.declared
    assert j.bones == ("humerus", "forearm") and j.kind == "hinge"
    assert j.vertices.dtype.kind == "i" and len(j.vertices) >= 2
    np.testing.assert_allclose(j.centre, arm.points[j.vertices].mean(axis=0))
    np.testing.assert_allclose(np.abs(j.axis), [0, 0, 1], atol=1e-12)
    (ball,) = emu.scenes.neck(1).joints()
    assert ball.kind == "ball" and ball.axis is None and len(ball.vertices) == 1
    s = gap_scene()
    d = s.add_joint("lower", "upper", centre=[1.5, 1.5, 0.5], axis=[0, 0, 2])
    assert isinstance(d, Joint) and d.declared and d.kind == "hinge" and len(d.vertices) == 0
    np.testing.assert_allclose(d.axis, [0, 0, 1])
    assert s.joints() == [d]
    with pytest.raises(ValueError, match="a joint needs two different bones"):
        s.add_joint("lower", "lower", centre=[0, 0, 0])
    with pytest.raises(ValueError, match="centre must be a finite 3-vector"):
        s.add_joint("lower", "upper", centre=[0, 0])


def test_a_weld_is_detected():
    pts, tets, lab = emu.procedural.block_mesh({"a": [(0, 0)], "b": [(1, 0)], "m": [(0, 1), (1, 1)]}, 1, depth=1)
    s = emu.Scene(pts, tets, warn=False)
    s.add_bone("a", lab == 0)
    s.add_bone("b", lab == 1)
    (j,) = s.joints()
    assert j.kind == "weld" and j.axis is None and len(j.vertices) >= 3


# ------------------------------------------------------------------ geometry
def test_bbox_diagonal():
    cube = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 2.0], [1, 2, 2]])
    assert emu.bbox_diagonal(cube) == pytest.approx(3.0)
    assert emu.bbox_diagonal(cube + 5.0) == pytest.approx(3.0)
    for bad in (np.zeros((0, 3)), np.zeros((4, 2)), np.zeros(3)):
        with pytest.raises(ValueError, match=r"non-empty \(n, 3\)"):
            emu.bbox_diagonal(bad)
    moved = cube.copy()
    moved[1] += [0.3, 0.0, 0.0]
    assert emu.vertex_error(moved, cube) == pytest.approx(0.1)
    assert emu.vertex_error(moved, cube, points=2 * cube) == pytest.approx(0.05)


# ------------------------------------------------------------------ the built-in fusiform scene
def test_fusiform_scene():
    s = emu.scenes.fusiform(3)
    m = emu.procedural.fusiform(3)
    np.testing.assert_array_equal(s.points, m.points)
    assert list(s.parts) == ["belly", "tendons"]
    np.testing.assert_array_equal(s.parts["tendons"].tets, np.flatnonzero(m.is_tendon))
    np.testing.assert_allclose(s.parts["belly"].fibers, m.fibers[~m.is_tendon], rtol=0, atol=1e-15)  # renormalised
    np.testing.assert_array_equal(s.pinned, np.sort(m.proximal))
    np.testing.assert_array_equal(s.vertex_sets["distal"], m.distal)
    both = emu.scenes.fusiform(3, pins=("proximal", "distal"), tendon_fraction=0.0, youngs=5e4)
    assert list(both.parts) == ["belly"] and len(both.parts["belly"].tets) == len(m.tets)
    assert both.parts["belly"].youngs == 5e4
    assert len(both.pinned) == len(m.proximal) + len(m.distal)
    assert len(emu.scenes.fusiform(tets=3000).tets) == len(emu.procedural.fusiform(tets=3000).tets)
    assert len(emu.scenes.fusiform(3, pins=()).pinned) == 0
    with pytest.raises(ValueError, match="unknown pin set.*'middle'"):
        emu.scenes.fusiform(2, pins=("middle",))


# ------------------------------------------------------------------ poses
def test_pose_about_takes_centre():
    R, t = emu.pose_about([0, 0, 1], 90, centre=[1, 1, 0])
    np.testing.assert_allclose(R @ [1, 1, 0] + t, [1, 1, 0], atol=1e-15)
    with pytest.raises(TypeError):
        emu.pose_about([0, 0, 1], 90, center=[1, 1, 0])
    with pytest.raises(ValueError, match="centre must be a finite 3-vector"):
        emu.pose_about([0, 0, 1], 90, [1, 1])


def test_connected_components_match_an_independent_graph_search():
    # emu.checks.connected_components (a union-find in the C++ core) against
    # scipy's connected components of the same vertex graph: the same pieces,
    # each labelled by its smallest vertex id; vertices of no tet alone.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components as scipy_components
    rng = np.random.default_rng(3)
    for n, m in ((30, 8), (200, 60), (500, 400), (7, 0)):
        tets = np.array([rng.choice(n, 4, replace=False) for _ in range(m)], dtype=np.int64).reshape(-1, 4)
        labels = emu.checks.connected_components(n, tets)
        rows = np.repeat(tets, 4, axis=1).ravel()
        cols = np.tile(tets, (1, 4)).ravel()
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
        count, ref = scipy_components(graph, directed=False)
        assert len(np.unique(labels)) == count
        for piece in range(count):
            members = np.flatnonzero(ref == piece)
            assert np.all(labels[members] == members.min())
    with pytest.raises(ValueError, match="outside"):
        emu.checks.connected_components(4, np.array([[0, 1, 2, 4]]))


def test_tet_vertices_are_the_sorted_unique_ids():
    rng = np.random.default_rng(3)
    tets = rng.integers(0, 50, (40, 4))
    np.testing.assert_array_equal(tet_vertices(tets, 60), np.unique(tets.ravel()))
    assert tet_vertices(tets[:0], 60).size == 0


def test_reprs_are_one_line_without_arrays():
    s = emu.scenes.fusiform(1, warn=False)
    sol = emu.solve(s, {"belly": 1e4}, "fem")
    r = repr(sol)
    assert "\n" not in r and len(r) < 200 and "array" not in r
    assert r.startswith("Solution(method='fem', status='converged'") and f"vertices={len(s.points)}" in r
    p = repr(s.parts["belly"])
    assert "\n" not in p and "array" not in p
    assert p == f"Part('belly', muscle, {len(s.parts['belly'].tets)} tets, youngs=60000, poisson=0.49)"
