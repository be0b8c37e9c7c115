"""Activation curves, scene files, `emu run` end to end, surfaces."""
import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

import emu
from emu.activation import Curve
from emu.scenefile import SceneFileError, load_scene_file
from emu.surface import boundary_faces


# ------------------------------------------------------------------ curves
def test_curve_interpolations():
    keys = [[0.0, 0.0], [1.0, 1.0], [2.0, 0.5]]
    lin = Curve(keys=keys, interpolation="linear")
    assert lin.value(0, -1.0) == 0.0 and lin.value(0, 5.0) == 0.5
    assert lin.value(0, 0.25) == pytest.approx(0.25)
    assert lin.value(0, 1.5) == pytest.approx(0.75)
    smooth = Curve(keys=keys, interpolation="smooth")
    assert smooth.value(0, 0.25) == pytest.approx(0.25 ** 2 * (3 - 0.5))  # smoothstep
    assert smooth.value(0, 0.5) == pytest.approx(0.5)
    vals = [smooth.value(0, t) for t in np.linspace(0, 2, 201)]
    assert min(vals) >= 0.0 and max(vals) <= 1.0  # no overshoot
    step = Curve(keys=keys, interpolation="step")
    assert step.value(0, 0.99) == 0.0 and step.value(0, 1.0) == 1.0
    per = Curve(per_frame=[0.1, 0.2], normalized=False)
    assert per.value(1, 123.0) == 0.2
    with pytest.raises(ValueError, match="has 2 values"):
        per.value(2, 0.0)


@pytest.mark.parametrize("kwargs,match", [
    (dict(keys=[[0, 0], [0, 1]]), "strictly increasing"),
    (dict(keys=[[0, -1]]), ">= 0"),
    (dict(keys=[[0, 2.0]]), r"\[0, 1\]"),
    (dict(keys=[[0, 0]], per_frame=[0]), "not both"),
    (dict(), "either keys or per_frame"),
    (dict(keys=[[0, 0]], interpolation="cubic"), "interpolation must be"),
    (dict(keys=[0, 1, 2]), r"\[time, value\] pairs"),
])
def test_curve_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Curve(**kwargs)


# -------------------------------------------------------------- scene files
GOOD = """
pins = ["proximal"]

[mesh.fusiform]
tets = 800

[materials.belly]
youngs = 5e4

[solver]
method = "emu"
alpha = 100.0

[frames]
count = 3
dt = 0.5

[activation.belly]
keys = [[0.0, 0.0], [1.0, 0.4]]
normalized = true
"""


def _write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_scene_file_loads(tmp_path):
    spec = load_scene_file(_write(tmp_path, GOOD))
    assert spec.frames == 3 and spec.dt == 0.5
    assert spec.scene.parts["belly"].youngs == 5e4
    assert len(spec.scene.pinned) > 0
    assert spec.activation(0)["belly"] == 0.0
    assert spec.activation(1)["belly"] == pytest.approx(0.2 * spec.scene.parts["belly"].max_activation)
    js = tmp_path / "scene.json"
    import tomllib
    js.write_text(json.dumps(tomllib.loads(GOOD)))
    assert load_scene_file(js).frames == 3


@pytest.mark.parametrize("edit,exc,match", [
    (lambda s: s.replace("[frames]", "[frames]\nspeed = 2"), SceneFileError, r"unknown key 'frames.speed'"),
    (lambda s: s.replace("count = 3", 'count = "three"'), SceneFileError, r"'frames.count' must be int"),
    (lambda s: s.replace("alpha = 100.0", "alpha = [1]"), SceneFileError, r"'solver.alpha' must be float"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", '[mesh]\npath = "nope.vtu"'), FileNotFoundError,
     "nope.vtu"),
    (lambda s: s.replace("[activation.belly]", "[activation.biceps]"), SceneFileError, "no muscle named 'biceps'"),
    (lambda s: s.replace('pins = ["proximal"]', 'pins = ["elbow"]'), SceneFileError, "unknown pin set 'elbow'"),
    (lambda s: s.replace("[materials.belly]", "[materials.bone]"), SceneFileError, "no part named 'bone'"),
    (lambda s: s.replace("youngs = 5e4", "stiffness = 5e4"), SceneFileError, "unknown key 'materials.belly.stiffness'"),
    (lambda s: s.replace("[mesh.fusiform]\ntets = 800", ""), SceneFileError, r"missing \[mesh\]"),
    (lambda s: s.replace("keys = [[0.0, 0.0], [1.0, 0.4]]", "keys = [[0.0, 3.0]]"), SceneFileError,
     r"activation.belly: .*\[0, 1\]"),
    (lambda s: s + "\n[output]\nvtu = 1\n", SceneFileError, "'output.vtu' must be bool"),
    (lambda s: s.replace("[frames]", "[frames\n"), SceneFileError, "not valid TOML"),
])
def test_scene_file_errors(tmp_path, edit, exc, match):
    with pytest.raises(exc, match=match):
        load_scene_file(_write(tmp_path, edit(GOOD)))


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="scene file not found"):
        load_scene_file(tmp_path / "absent.toml")


# ------------------------------------------------------------- emu run (CLI)
def test_emu_run_end_to_end(tmp_path):
    scene = _write(tmp_path, GOOD)
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "emu.cli", "run", str(scene), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "frame 3/3" in r.stdout
    root = ET.parse(out / "series.pvd").getroot()
    files = [d.attrib["file"] for d in root.iter("DataSet")]
    times = [float(d.attrib["timestep"]) for d in root.iter("DataSet")]
    assert files == ["frame_0000.vtu", "frame_0001.vtu", "frame_0002.vtu"]
    assert times == [0.0, 0.5, 1.0]
    spec = load_scene_file(scene)
    for k, f in enumerate(files):
        m = meshio.read(out / f)
        assert len(m.points) == len(spec.scene.points)
        for key in ("part", "fiber", "activation", "J"):
            assert key in m.cell_data
        assert "displacement" in m.point_data
        obj = (out / f.replace(".vtu", ".obj")).read_text().splitlines()
        assert sum(1 for line in obj if line.startswith("f ")) == len(boundary_faces(spec.scene.tets))
    last = meshio.read(out / files[-1])
    assert np.abs(last.point_data["displacement"]).max() > 1e-3  # it moved
    log = json.loads((out / "log.json").read_text())
    assert len(log["frames"]) == 3 and all(f["converged"] for f in log["frames"])
    assert log["frames"][1]["activation"]["belly"] == pytest.approx(0.2 * 1e5)


def test_return_to_rest_converges():
    # activation up, then back to zero from a warm start: the solve must reach the
    # rest shape (round-off near rest used to stall the line search)
    m = emu.meshes.fusiform(tets=800)
    s = emu.Scene(m.points, m.tets, warn=False)
    s.add_muscle("belly", ~m.is_tendon, m.fibers[~m.is_tendon])
    s.add_tendon("t", m.is_tendon)
    s.pin(m.proximal)
    for method in ("emu", "fem"):
        solver = emu.Solver(s, method)
        up = solver.solve({"belly": 1e4})
        down = solver.solve({"belly": 0.0}, initial=up)
        assert down.converged, (method, down.status)
        assert emu.vertex_error(down, m.points) < 1e-5, method


# ------------------------------------------------------------------ surface
def test_boundary_surface_is_closed_and_outward():
    m = emu.meshes.fusiform(3)
    f = boundary_faces(m.tets)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed, manifold
    p = m.points
    vol = np.einsum("ij,ij->i", p[f[:, 0]], np.cross(p[f[:, 1]], p[f[:, 2]])).sum() / 6.0
    assert vol == pytest.approx(emu.checks.signed_volumes(p, m.tets).sum(), rel=1e-10)  # outward normals


def test_emu_info_on_a_scene_file(tmp_path):
    scene = _write(tmp_path, GOOD)
    r = subprocess.run([sys.executable, "-m", "emu.cli", "info", str(scene)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert "BLAS" in r.stdout and "part belly: muscle" in r.stdout
    assert "frames: 3 x 0.5 s" in r.stdout and "activation belly: 2 keys" in r.stdout
    bad = _write(tmp_path, GOOD.replace("[frames]", "[frames]\nspeed = 1"), "bad.toml")
    r = subprocess.run([sys.executable, "-m", "emu.cli", "info", str(bad)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "unknown key 'frames.speed'" in r.stderr
