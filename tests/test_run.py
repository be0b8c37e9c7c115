"""Running a scene file over its frames (emu.run_scene, code in
emu.app.run): warm-started solves, a VTU per frame and the .pvd series, OBJ
surfaces, log.json. The schema: test_scenefile.py; the `emu` command: test_cli.py."""
import json
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import emu
from emu.core.fibers import attachment_fibers
from emu.io import boundary_faces
from emu import run_scene
from emu import load_scene_file

from conftest import bone_muscle_bone

GOOD = """
pins = ["proximal"]

[mesh.fusiform]
tets = 800

[solver]
method = "emu"
alpha = 100.0

[frames]
count = 3
dt = 0.5

[activation.belly]
keys = [[0.0, 0.0], [1.0, 0.4]]
"""


def test_run_scene_writes_frames_series_surfaces_and_log(tmp_path):
    p = tmp_path / "scene.toml"
    p.write_text(GOOD)
    spec = load_scene_file(p)
    out = tmp_path / "out"
    kept = {}
    lines = []
    log = run_scene(spec, str(out), progress=lines.append, on_frame=lambda k, sol: kept.__setitem__(k, sol))
    assert any("frame 3/3" in line for line in lines)
    root = ET.parse(out / "series.pvd").getroot()
    files = [d.attrib["file"] for d in root.iter("DataSet")]
    times = [float(d.attrib["timestep"]) for d in root.iter("DataSet")]
    assert files == ["frame_0000.vtu", "frame_0001.vtu", "frame_0002.vtu"]
    assert times == [0.0, 0.5, 1.0]
    belly = spec.scene.parts["belly"].tets
    for k, f in enumerate(files):
        m = meshio.read(out / f)
        np.testing.assert_allclose(m.points, kept[k].positions, rtol=0, atol=1e-12)
        for key in ("part", "fiber", "activation", "J"):
            assert key in m.cell_data
        assert "displacement" in m.point_data
        # the activation written is the frame's, on the muscle's tets
        act = np.asarray(m.cell_data["activation"][0]).ravel()
        np.testing.assert_allclose(act[belly], spec.activation(k)["belly"])
        np.testing.assert_array_equal(np.delete(act, belly), 0.0)
        obj = (out / f.replace(".vtu", ".obj")).read_text().splitlines()
        assert sum(1 for line in obj if line.startswith("f ")) == len(boundary_faces(spec.scene.tets))
    last = meshio.read(out / files[-1])
    assert np.abs(last.point_data["displacement"]).max() > 1e-3  # it moved
    on_disk = json.loads((out / "log.json").read_text())
    assert on_disk["frames"] == json.loads(json.dumps(log["frames"], default=float))
    assert len(log["frames"]) == 3 and all(f["converged"] for f in log["frames"])
    assert all(f["inverted_tets"] == 0 for f in log["frames"])   # logged per frame
    assert log["frames"][1]["activation"]["belly"] == pytest.approx(0.2 * 1e5)
    assert not log["interrupted"]


def test_run_scene_with_a_scripted_bone(tmp_path):
    s, m, _ = bone_muscle_bone(0.15)
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
centre = [0.0, 0.0, {0.9 * m.length}]
angle = [[0.0, 0.0], [1.0, 20.0]]
""")
    out = tmp_path / "out"
    log = run_scene(load_scene_file(tmp_path / "arm.toml"), str(out), progress=lambda line: None)
    bone = np.unique(m.tets[s.parts["distal"].tets].ravel())
    for k, deg in enumerate([0.0, 10.0, 20.0]):
        x = meshio.read(out / f"frame_{k:04d}.vtu").points
        R, t = emu.pose_about([1, 0, 0], deg, [0, 0, 0.9 * m.length])
        np.testing.assert_allclose(x[bone], m.points[bone] @ R.T + t, atol=1e-9)
    assert [f["bone_angles_deg"]["distal"] for f in log["frames"]] == pytest.approx([0.0, 10.0, 20.0])
    assert json.loads((out / "log.json").read_text())["frames"][2]["bone_angles_deg"]["distal"] == \
        pytest.approx(20.0)


def test_run_scene_writes_the_fibres_it_solved_with(tmp_path):
    """A muscle given without fibres gets its Laplace field for the solve (not
    stored in the scene); the frames show that field, deformed."""
    p = tmp_path / "arm.toml"
    p.write_text("[mesh.arm]\nresolution = 1\n[frames]\ncount = 1\n[output]\nobj = false\n")
    spec = load_scene_file(p)
    for name in spec.scene.muscles:
        spec.scene.parts[name].fibers = None     # the arm resolves them; make them lazy again
    run_scene(spec, str(tmp_path / "out"), progress=lambda line: None)
    assert all(spec.scene.parts[n].fibers is None for n in spec.scene.muscles)
    fib = np.asarray(meshio.read(tmp_path / "out" / "frame_0000.vtu").cell_data["fiber"][0])
    s = spec.scene
    for name in s.muscles:   # at rest (no activation) the deformed fibres are the rest ones
        p = s.parts[name]
        ref = attachment_fibers(s.points, s.tets, name, p.tets, s.attachments(name))
        np.testing.assert_allclose(fib[p.tets], ref, atol=1e-8)


def test_run_scene_logs_and_sums_up_frames_settled_by_fem(tmp_path, monkeypatch):
    """Frames whose error estimate does not certify itself (here forced: a
    certificate no second FEM step passes) are settled by FEM: each frame's
    log says so, the progress line says so, and the run's summary counts
    them; a run where every estimate certified itself has no summary."""
    import sys
    from emu.app.run import accuracy_summary
    p = tmp_path / "scene.toml"
    p.write_text(GOOD.replace("alpha = 100.0", "accuracy = 0.001"))
    spec = load_scene_file(p)
    log = run_scene(spec, str(tmp_path / "plain"), progress=lambda line: None)
    assert all(f["error_estimate_certified"] for f in log["frames"][1:])
    assert accuracy_summary(log) == ""
    monkeypatch.setattr(sys.modules["emu.solve.estimate"], "CERTIFY_CONTRACTION", 0.0)
    monkeypatch.setattr(sys.modules["emu.solve.estimate"], "STEP_FRACTION", 0.0)
    lines = []
    with pytest.warns(emu.AccuracyWarning, match="could not certify itself"):
        log = run_scene(load_scene_file(p), str(tmp_path / "settled"), progress=lines.append)
    settled = [f["frame"] for f in log["frames"] if f["settled_by_fem"]]
    assert settled == [1, 2]   # frame 0 is the rest state: nothing to correct
    assert all("settled by a FEM solve" in log["frames"][k]["error_estimate_note"] for k in settled)
    assert sum("settled by FEM" in line for line in lines) == 2
    assert accuracy_summary(log).startswith("2 of 3 frame(s) settled by a FEM solve")
