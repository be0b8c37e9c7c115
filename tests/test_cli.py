"""The `emu` command line (emu.app.cli), run as a user runs
it: a separate process through ``python -m emu`` (the entry point
pyproject.toml names)."""
import json
import subprocess
import sys
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import emu

from conftest import bone_muscle_bone
from test_scenefile import GOOD, write


def emu_cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "emu", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_emu_run_end_to_end(tmp_path):
    scene = write(tmp_path, GOOD)
    out = tmp_path / "out"
    r = emu_cli("run", str(scene), "--out", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "frame 3/3" in r.stdout
    files = [d.attrib["file"] for d in ET.parse(out / "series.pvd").getroot().iter("DataSet")]
    assert files == ["frame_0000.vtu", "frame_0001.vtu", "frame_0002.vtu"]
    assert all((out / f).exists() and (out / f.replace(".vtu", ".obj")).exists() for f in files)
    log = json.loads((out / "log.json").read_text())
    assert len(log["frames"]) == 3 and all(f["converged"] for f in log["frames"])
    assert [(p["name"], p["kind"]) for p in log["parts"]] == [("belly", "muscle"), ("tendons", "tendon")]
    assert "o belly" in (out / "frame_0000.obj").read_text()
    assert (out / "preview.png").stat().st_size > 10_000 and "preview.png" in r.stdout
    # a rerun with fewer frames into the same folder removes the first run's
    # files (its frame 2, its preview) and nothing else
    (out / "notes.txt").write_text("mine")
    short = write(tmp_path, GOOD.replace("count = 3", "count = 2"), name="short.toml")
    assert "count = 3" in GOOD
    r = emu_cli("run", str(short), "--out", str(out), "--no-preview")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "removed 9 file(s) an earlier run wrote" in r.stdout, r.stdout
    assert sorted(p.name for p in out.iterdir()) == ["frame_0000.obj", "frame_0000.vtu", "frame_0001.obj",
                                                      "frame_0001.vtu", "log.json", "notes.txt", "series.pvd"]


def test_emu_run_reports_a_missing_scene_file(tmp_path):
    r = emu_cli("run", str(tmp_path / "absent.toml"), "--out", str(tmp_path / "out"))
    assert r.returncode == 2 and "scene file not found" in r.stderr, r.stderr


def test_emu_compare(tmp_path):
    out = tmp_path / "cmp"
    r = emu_cli("compare", "--tets", "800", "--out", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    summary = json.loads((out / "summary.json").read_text())
    res = summary["results"]
    assert set(res) == {"fem", "emu_newton_krylov"} and all(v["converged"] for v in res.values())
    assert 0.05 < res["fem"]["shortening"] < 0.5            # a = 5e4 shortens the muscle visibly
    assert 1e-4 < res["emu_newton_krylov"]["vertex_error_to_fem"] < 5e-2
    m = meshio.read(out / "fem.vtu")
    act = np.asarray(m.cell_data["activation"][0]).ravel()
    belly = emu.scenes.fusiform(tets=800).parts["belly"].tets
    np.testing.assert_allclose(act[belly], 5e4)


def test_emu_solve_a_labelled_mesh(tmp_path):
    s, m, _ = bone_muscle_bone(0.15, r=2)
    part = np.zeros(len(m.tets), np.int32)
    for i, name in enumerate(["belly", "proximal", "distal"]):
        part[s.parts[name].tets] = i
    mesh = tmp_path / "bmb.vtu"
    emu.io.write(mesh, m.points, m.tets, cell_data={"part": part})
    (tmp_path / "scene.json").write_text(json.dumps({"parts": [
        {"id": 0, "name": "belly", "kind": "muscle"}, {"id": 1, "name": "proximal", "kind": "bone"},
        {"id": 2, "name": "distal", "kind": "bone"}]}))
    out = tmp_path / "sol.vtu"
    # no fibre cell data: the loader needs the Laplace field (or a direction), and
    # says how to ask for it on the command line; asked for, it solves
    r = emu_cli("solve", str(mesh), "--absolute-activation", "belly=1e4", "--out", str(out))
    assert r.returncode == 2 and "no 'fiber' cell data" in r.stderr and "--fibers belly=laplace" in r.stderr, \
        r.stdout + r.stderr
    r = emu_cli("solve", str(mesh), "--fibers", "belly=laplace", "--absolute-activation", "belly=1e4", "--method", "fem")
    assert r.returncode == 0, r.stdout + r.stderr
    emu.io.write(mesh, m.points, m.tets, cell_data={"part": part, "fiber": np.tile([0.0, 0.0, 1.0], (len(m.tets), 1))})
    r = emu_cli("solve", str(mesh), "--absolute-activation", "belly=1e4", "--method", "fem", "--out", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    sol = meshio.read(out)
    assert (tmp_path / "sol.png").stat().st_size > 5_000 and "wrote " + str(tmp_path / "sol.png") in r.stdout
    act = np.asarray(sol.cell_data["activation"][0]).ravel()
    np.testing.assert_allclose(act[s.parts["belly"].tets], 1e4)
    np.testing.assert_array_equal(act[s.parts["proximal"].tets], 0.0)
    assert np.abs(sol.point_data["displacement"]).max() > 1e-3
    assert "hint" not in r.stdout          # FEM is the faster method at this size: no hint
    r = emu_cli("solve", str(mesh), "--absolute-activation", "belly=1e4", "--method", "emu")
    assert r.returncode == 0 and "hint: at " in r.stdout and "method='fem'" in r.stdout, r.stdout
    # --activation is a fraction of the muscle's maximum, as in scene files (the
    # belly's is 1e5): 0.1 is the 1e4 above; an absolute number there is refused
    out2 = tmp_path / "normalised.vtu"
    r = emu_cli("solve", str(mesh), "--activation", "belly=0.1", "--method", "fem", "--out", str(out2), "--no-preview")
    assert r.returncode == 0, r.stdout + r.stderr
    np.testing.assert_allclose(np.asarray(meshio.read(out2).cell_data["activation"][0]).ravel(), act)
    assert not (tmp_path / "normalised.png").exists()
    r = emu_cli("solve", str(mesh), "--activation", "belly=1e4", "--method", "fem")
    assert r.returncode == 2 and "--absolute-activation belly=10000" in r.stderr, r.stderr


def test_emu_info_on_a_scene_file(tmp_path):
    scene = write(tmp_path, GOOD)
    r = emu_cli("info", str(scene), timeout=120)
    assert r.returncode == 0, r.stderr
    assert "BLAS" in r.stdout and "part belly: muscle" in r.stdout
    assert "frames: 3 x 0.5 s" in r.stdout and "activation belly: 2 keys" in r.stdout
    bad = write(tmp_path, GOOD.replace("[frames]", "[frames]\nspeed = 1"), "bad.toml")
    r = emu_cli("info", str(bad), timeout=120)
    assert r.returncode == 2 and "unknown key 'frames.speed'" in r.stderr


def test_emu_demo_end_to_end(tmp_path):
    out = tmp_path / "demo"
    r = emu_cli("demo", "--resolution", "1", "--frames", "5", "--out", str(out), timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    for name in ("contact_sheet.png", "elbow_angle.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10000
    files = [d.attrib["file"] for d in ET.parse(out / "series.pvd").getroot().iter("DataSet")]
    assert len(files) == 5
    m = meshio.read(out / files[1])  # t = 0.5 s, the flexor's peak: the forearm has turned
    assert np.abs(m.point_data["displacement"]).max() > 1e-3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["all_converged"] and summary["frames"] == 5
    angles = summary["elbow_angle_deg"]
    assert angles[1] > 10 and abs(angles[2]) < 0.1 and angles[3] < -3, angles  # flexes, back, extends
    assert summary["max_angle_difference_deg"] < 3.0
    # both methods' whole times are reported side by side, EMU's parts beside its total
    assert summary["emu_solve_s"] > 0 and summary["fem_time_s"] > 0 and summary["emu_error_estimate_s"] > 0
    assert summary["emu_time_s"] >= summary["emu_solve_s"] + summary["emu_error_estimate_s"]
    assert "time over the frames: EMU" in r.stdout and "FEM" in r.stdout
    log = json.loads((out / "log.json").read_text())
    assert [f["bone_angles_deg"]["forearm"] for f in log["frames"]] == pytest.approx(angles)


def test_emu_data_and_scene_names(tmp_path):
    """`emu data NAME` fetches (here from the shared offline copy: conftest sets
    EMU_DATA_DIR) and says where; `emu info NAME` / `emu solve NAME` take the
    name in place of a mesh; an unknown name is an error that lists the known."""
    from conftest import shared_raw

    shared_raw()
    r = emu_cli("data", "simple_joint")
    assert r.returncode == 0, r.stderr
    assert "simple_joint: " in r.stdout and "116b1308ce99" in r.stdout
    path = r.stdout.split("simple_joint: ")[1].split()[0]
    assert path.endswith("simple_joint.vtu") and meshio.read(path).points.shape == (2452, 3)
    r = emu_cli("info", "simple_joint")
    assert r.returncode == 0, r.stderr
    assert "bottom_bone" in r.stdout and "hinge" in r.stdout
    r = emu_cli("data", "no_such_scene")
    assert r.returncode == 1 and "no_such_scene" in r.stderr and "simple_joint" in r.stderr


def test_cli_messages_a_user_can_act_on(tmp_path):
    """A mesh given to emu run points at emu solve; a warning prints as one
    line (no Python source line); a muscle lying on a bone apart from it is
    named in that warning."""
    from test_io import _box

    muscle_points, muscle_tets = _box([0, 0, 0], [1, 1, 2], 4)
    bone_points, bone_tets = _box([0, 0, -1], [1, 1, 0], 3)
    top_points, top_tets = _box([0, 0, 2], [1, 1, 3], 4)
    points = np.vstack([muscle_points, bone_points, top_points])
    tets = np.vstack([muscle_tets, bone_tets + len(muscle_points), top_tets + len(muscle_points) + len(bone_points)])
    part = np.concatenate([np.zeros(len(muscle_tets), int), np.ones(len(bone_tets), int), np.full(len(top_tets), 2)])
    mesh = tmp_path / "m.vtu"
    emu.io.write(mesh, points, tets, cell_data={"part": part}, part_names={0: "belly", 1: "floor", 2: "roof"})
    r = emu_cli("run", str(mesh))
    assert r.returncode == 2 and "is a mesh, not a scene file" in r.stderr and f"emu solve {mesh}" in r.stderr, r.stderr
    r = emu_cli("solve", str(mesh), "--kind", "floor=bone", "roof=bone", "--fibers", "belly=0,0,1", "--weld",
                "--absolute-activation", "belly=1e3", "--method", "fem")
    assert r.returncode == 0, r.stdout + r.stderr
    warnings_ = [line for line in r.stderr.splitlines() if line.strip()]
    assert any(w.startswith("emu: warning: ") and "lies on bone 'floor'" in w for w in warnings_), r.stderr
    assert all(w.startswith("emu: warning: ") for w in warnings_), r.stderr      # nothing else: no source lines


def test_cli_exit_status_and_arguments_a_user_reaches_for(tmp_path):
    """--version; emu run --method fem (the scene file's method overridden);
    a frame that does not converge makes the run exit 1 (after writing what
    it has); a folder for a scene file, --threads 0 and a bad activation value
    are one-line errors (exit 2); emu solve --out into a folder that does not
    exist yet creates it."""
    r = emu_cli("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"emu {emu.__version__}", r.stdout + r.stderr
    scene = write(tmp_path, GOOD)
    r = emu_cli("run", str(scene), "--out", str(tmp_path / "fem"), "--method", "fem", "--no-preview")
    assert r.returncode == 0, r.stdout + r.stderr
    log = json.loads((tmp_path / "fem" / "log.json").read_text())
    assert all(f["error_estimate"] is None for f in log["frames"])   # FEM: no EMU estimate
    assert "--method fem: leaving out the scene file's alpha (options of EMU only)" in r.stdout, r.stdout
    assert "frame(s), fem (setup" in r.stdout, r.stdout
    r = emu_cli("run", str(scene), "--out", str(tmp_path / "capped"), "-O", "max_iterations=1", "--no-preview")
    assert r.returncode == 1 and "NOT converged" in r.stdout, r.stdout + r.stderr
    assert (tmp_path / "capped" / "log.json").exists()
    r = emu_cli("run", str(tmp_path))
    assert r.returncode == 2 and "is a folder: give one scene file" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    r = emu_cli("run", str(scene), "--threads", "0")
    assert r.returncode == 2 and "at least 1" in r.stderr and "Traceback" not in r.stderr, r.stderr
    s, _, _ = bone_muscle_bone(0.2, r=2)
    mesh = tmp_path / "bmb.vtu"
    part = np.full(len(s.tets), -1)
    for k, p in enumerate(s.parts.values()):
        part[p.tets] = k
    emu.io.write(mesh, s.points, s.tets, cell_data={"part": part}, part_names={0: "proximal", 1: "distal", 2: "belly"})
    common = ["--kind", "proximal=bone", "distal=bone", "--fibers", "belly=0,0,1", "--method", "fem"]
    r = emu_cli("solve", str(mesh), *common, "--activation", "belly=abc")
    assert r.returncode == 2 and r.stderr.startswith("emu: error: --activation belly: 'abc' is not a number"), r.stderr
    out = tmp_path / "new" / "deeper" / "sol.vtu"
    r = emu_cli("solve", str(mesh), *common, "--activation", "belly=0.3", "--out", str(out), "--no-preview")
    assert r.returncode == 0 and out.exists(), r.stdout + r.stderr
