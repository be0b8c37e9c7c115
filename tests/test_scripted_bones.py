"""Scripted bones: prescribed rigid motions and joint consistency (scene files
with scripted bones: test_scenefile.py, test_run.py)."""
import numpy as np
import pytest

import emu
from conftest import bone_muscle_bone, shared_path, shared_scene


def _bone_muscle_bone():
    s, m, _ = bone_muscle_bone(0.15)
    return s, m


def test_rotation_helpers():
    R = emu.rotation([0, 0, 2], 90)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    R, t = emu.pose_about([0, 0, 1], 90, [1, 1, 0])
    np.testing.assert_allclose(R @ [1, 1, 0] + t, [1, 1, 0], atol=1e-15)  # the centre stays
    np.testing.assert_allclose(R @ [2, 1, 0] + t, [1, 2, 0], atol=1e-15)


@pytest.mark.parametrize("method", ["fem", "emu"])
def test_scripted_bone_follows_its_motion_and_pulls_the_muscle(method):
    s, m = _bone_muscle_bone()
    R, t = emu.pose_about([1, 0, 0], 20, [0, 0, 0.9 * m.length])
    t = t + [0, 0, 0.5]
    sol = emu.solve(s, {}, method, bone_poses={"distal": (R, t)})
    assert sol.converged, sol.status
    bone = np.unique(s.tets[s.parts["distal"].tets].ravel())
    np.testing.assert_allclose(sol.positions[bone], s.points[bone] @ R.T + t, atol=1e-12)
    fixed = np.unique(s.tets[s.parts["proximal"].tets].ravel())
    np.testing.assert_array_equal(sol.positions[fixed], s.points[fixed])
    belly = np.setdiff1d(np.unique(s.tets[s.parts["belly"].tets].ravel()), np.union1d(bone, fixed))
    assert np.abs(sol.positions[belly] - s.points[belly]).max() > 0.1  # the muscle was dragged along
    # a 4x4 transform means the same
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    sol4 = emu.solve(s, {}, method, bone_poses={"distal": M})
    np.testing.assert_allclose(sol4.positions, sol.positions, atol=1e-9)


def test_bone_pose_errors():
    s, m = _bone_muscle_bone()
    with pytest.raises(ValueError, match="not a rotation"):
        emu.solve(s, {}, "fem", bone_poses={"distal": (2 * np.eye(3), np.zeros(3))})
    with pytest.raises(ValueError, match="no bone named 'ulna'"):
        emu.solve(s, {}, "fem", bone_poses={"ulna": (np.eye(3), np.zeros(3))})
    with pytest.raises(ValueError, match=r"\(R, t\) or a 4x4"):
        emu.solve(s, {}, "fem", bone_poses={"distal": np.eye(3)})
    with pytest.raises(TypeError, match="bone_poses must be a dict"):
        emu.solve(s, {}, "fem", bone_poses=[np.eye(4)])


def test_hinge_must_rotate_about_its_axis():
    sc = shared_scene("simple_joint", warn=False)
    p = sc.points
    hinge = (2450, 2451)
    with pytest.raises(ValueError, match="share vertex .* a joint must stay together"):
        emu.solve(sc, {}, "fem", bone_poses={"bottom_bone": emu.pose_about([1, 0, 0], 10, [0, 0, 0])})
    pose = emu.pose_about(p[hinge[1]] - p[hinge[0]], 10, p[hinge[0]])
    sol = emu.solve(sc, {}, "fem", bone_poses={"bottom_bone": pose})
    assert sol.converged
    np.testing.assert_allclose(sol.positions[list(hinge)], p[list(hinge)], atol=1e-12)


def test_joints_are_detected():
    s, m = _bone_muscle_bone()
    assert s.joints() == []  # the two bones share no vertex
    sc = shared_scene("simple_joint", warn=False)
    (j,) = sc.joints()
    assert j.kind == "hinge" and set(j.bones) == {"top_bone", "bottom_bone"}
    np.testing.assert_array_equal(j.vertices, [2450, 2451])
    d = sc.points[2451] - sc.points[2450]
    np.testing.assert_allclose(abs(j.axis @ d), np.linalg.norm(d))
    # rotating about the detected axis through the detected centre keeps the hinge together
    sol = emu.solve(sc, {}, "fem", bone_poses={"bottom_bone": emu.pose_about(j.axis, 15, j.centre)})
    assert sol.converged
    assert emu.io.load_scene(shared_path("big_muscle"), warn=False).joints() == []
