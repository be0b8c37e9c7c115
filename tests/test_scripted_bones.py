"""Scripted bones: prescribed rigid motions, joint consistency, scene files."""
import json
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

import emu
from conftest import bone_muscle_bone

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


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
    path = DATA / "simple_joint" / "simple_joint.vtu"
    if not path.exists():
        pytest.skip("shared data folder not present")
    sc = emu.io.load_scene(path, warn=False)
    p = sc.points
    hinge = (2450, 2451)
    with pytest.raises(ValueError, match="share vertex .* a joint must stay together"):
        emu.solve(sc, {}, "fem", bone_poses={"bottom_bone": emu.pose_about([1, 0, 0], 10, [0, 0, 0])})
    pose = emu.pose_about(p[hinge[1]] - p[hinge[0]], 10, p[hinge[0]])
    sol = emu.solve(sc, {}, "fem", bone_poses={"bottom_bone": pose})
    assert sol.converged
    np.testing.assert_allclose(sol.positions[list(hinge)], p[list(hinge)], atol=1e-12)


def test_scene_file_with_a_scripted_bone(tmp_path):
    s, m = _bone_muscle_bone()
    part = np.zeros(len(m.tets), np.int32)
    for i, name in enumerate(["belly", "proximal", "distal"]):
        part[s.parts[name].tets] = i
    emu.io.write(tmp_path / "arm.vtu", m.points, m.tets,
                 cell_data={"part": part, "fiber": np.tile([0.0, 0.0, 1.0], (len(m.tets), 1))})
    (tmp_path / "scene.json").write_text(json.dumps({"parts": [
        {"id": 0, "name": "belly", "kind": "muscle"}, {"id": 1, "name": "proximal", "kind": "bone"},
        {"id": 2, "name": "distal", "kind": "bone"}]}))
    (tmp_path / "arm.toml").write_text(f"""
[mesh]
path = "arm.vtu"
fibers = "laplace"

[solver]
method = "fem"

[frames]
count = 3
dt = 0.5

[bones.distal]
axis = [1.0, 0.0, 0.0]
center = [0.0, 0.0, {0.9 * m.length}]
angle = [[0.0, 0.0], [1.0, 20.0]]
""")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "emu.cli", "run", str(tmp_path / "arm.toml"), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    bone = np.unique(m.tets[s.parts["distal"].tets].ravel())
    for k, deg in enumerate([0.0, 10.0, 20.0]):
        x = meshio.read(out / f"frame_{k:04d}.vtu").points
        R, t = emu.pose_about([1, 0, 0], deg, [0, 0, 0.9 * m.length])
        np.testing.assert_allclose(x[bone], m.points[bone] @ R.T + t, atol=1e-9)
    log = json.loads((out / "log.json").read_text())
    assert [f["bone_angles_deg"]["distal"] for f in log["frames"]] == pytest.approx([0.0, 10.0, 20.0])
    bad = (tmp_path / "arm.toml").read_text().replace("[bones.distal]", "[bones.belly]")
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(emu.scenefile.SceneFileError, match="no bone named 'belly'"):
        emu.scenefile.load_scene_file(tmp_path / "bad.toml")


def test_joints_are_detected():
    s, m = _bone_muscle_bone()
    assert s.joints() == []  # the two bones share no vertex
    path = DATA / "simple_joint" / "simple_joint.vtu"
    if not path.exists():
        pytest.skip("shared data folder not present")
    sc = emu.io.load_scene(path, warn=False)
    (j,) = sc.joints()
    assert j["kind"] == "hinge" and set(j["bones"]) == {"top_bone", "bottom_bone"}
    np.testing.assert_array_equal(j["vertices"], [2450, 2451])
    d = sc.points[2451] - sc.points[2450]
    np.testing.assert_allclose(abs(j["axis"] @ d), np.linalg.norm(d))
    # rotating about the detected axis through the detected centre keeps the hinge together
    sol = emu.solve(sc, {}, "fem", bone_poses={"bottom_bone": emu.pose_about(j["axis"], 15, j["centre"])})
    assert sol.converged
    big = DATA / "big_muscle" / "big_muscle.vtu"
    assert emu.io.load_scene(big, warn=False).joints() == []
