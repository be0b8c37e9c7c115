"""The two real scenes from the authors' research code (/work/shared/data):
they load, their defects are reported, FEM and EMU solve them and agree."""
import warnings

import numpy as np
import pytest

import emu

from conftest import shared_path

ACTIVATION = {"muscle": 1e4}
# measured EMU(alpha = 100 mu, k = 48) vertex errors to FEM: simple_joint 1.1e-3, big_muscle 1.4e-2
ERROR_BOUND = {"simple_joint": 5e-3, "big_muscle": 4e-2}


def load(name):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = emu.io.load_scene(shared_path(name))
    return scene, [w for w in caught if issubclass(w.category, emu.MeshWarning)]


@pytest.fixture(scope="module", params=["simple_joint", "big_muscle"])
def solved(request):
    name = request.param
    scene, _ = load(name)
    fem = emu.solve(scene, ACTIVATION, "fem")
    return name, scene, fem


def test_simple_joint_defects_are_reported():
    scene, caught = load("simple_joint")
    messages = [str(w.message) for w in caught]
    assert any("negative volume" in s and "reoriented" in s for s in messages), messages
    assert any("sliver" in s for s in messages), messages
    rep = scene.mesh_report
    assert len(rep.reoriented) == 1
    assert len(rep.slivers) >= 1
    assert rep.min_quality < 0.05
    # the reoriented tet now has positive volume
    t = scene.tets[rep.reoriented[0]]
    p = scene.points[t]
    assert np.dot(p[1] - p[0], np.cross(p[2] - p[0], p[3] - p[0])) > 0


def test_big_muscle_is_clean():
    scene, caught = load("big_muscle")
    assert not caught, [str(w.message) for w in caught]
    assert len(scene.mesh_report.reoriented) == 0


@pytest.mark.parametrize("name,parts", [("simple_joint", {"muscle": "muscle", "top_bone": "bone",
                                                          "bottom_bone": "bone"}),
                                        ("big_muscle", {"muscle": "muscle", "bone_1": "bone", "bone_2": "bone"})])
def test_parts_and_pins(name, parts):
    scene, _ = load(name)
    assert {n: p.kind for n, p in scene.parts.items()} == parts
    assert sum(len(p.tets) for p in scene.parts.values()) == len(scene.tets)
    f = scene.parts["muscle"].fibers
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.0, atol=1e-9)
    # fixed bones: all their vertices are held, and only bone tets are dropped from the model
    pins = set(scene.model_pins()[0].tolist())
    for p in scene.parts.values():
        if p.kind == "bone":
            assert set(scene.tets[p.tets].ravel().tolist()) <= pins
    assert len(scene.model_tets) == len(scene.parts["muscle"].tets)


def test_fem_converges_and_holds_bones(solved):
    name, scene, fem = solved
    assert fem.converged, fem.status
    pins = scene.model_pins()[0]
    np.testing.assert_array_equal(fem.positions[pins], scene.points[pins])
    moved = emu.vertex_error(fem.positions, scene.points)
    assert moved > 1e-2, "activation 1e4 must visibly contract the muscle"


def test_emu_converges_close_to_fem(solved):
    name, scene, fem = solved
    sol = emu.solve(scene, ACTIVATION, "emu", alpha=100.0)
    assert sol.converged, sol.status
    pins = scene.model_pins()[0]
    np.testing.assert_array_equal(sol.positions[pins], scene.points[pins])
    err = emu.vertex_error(sol, fem)
    assert err < ERROR_BOUND[name]
    # EMU is a different discretisation: it is close to FEM, not identical
    assert err > 1e-8


def test_missing_shared_data_skips_with_the_path():
    """Every test reads the shared scenes through conftest.shared_path: absent,
    the test is skipped, naming where it looked."""
    with pytest.raises(pytest.skip.Exception, match=r"shared data not found at .*no_such_scene\.vtu"):
        shared_path("no_such_scene")
