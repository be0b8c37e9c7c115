"""USD output (usd-core): the stage read back by Pixar's library has a Mesh
prim per part with a time sample per frame holding that part's surface at
that frame, the muscles' colour following their activation; emu run --usd
streams one; without usd-core the message says how to get it."""
import subprocess
import sys

import numpy as np
import pytest

import emu
from emu.io.obj import boundary_faces

pxr = pytest.importorskip("pxr", reason="USD output needs usd-core (pip install emu[usd])")
from pxr import Usd, UsdGeom  # noqa: E402


def test_a_stage_holds_every_part_at_every_frame(tmp_path):
    scene = emu.scenes.arm(1)
    solver = emu.Solver(scene, "fem")
    acts = [{"flexor": a} for a in (0.0, 0.3, 0.6)]
    frames = [solver.solve(a, normalized=True).positions for a in acts]
    path = emu.io.write_usd(tmp_path / "arm.usda", scene, frames, dt=0.25, activations=acts)
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == pytest.approx(4.0)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 2)
    assert stage.GetDefaultPrim().GetPath() == "/emu"
    meshes = {p.GetName(): UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)}
    assert list(meshes) == list(scene.parts)
    faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
    for name, mesh in meshes.items():
        mine = faces[np.isin(faces_tet, scene.parts[name].tets)]
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
        index = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        assert len(counts) == len(mine) and np.all(counts == 3)
        assert mesh.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
        for k, x in enumerate(frames):
            pts = np.asarray(mesh.GetPointsAttr().Get(k), dtype=np.float64)
            # the stage's triangles are the part's boundary triangles at frame k
            np.testing.assert_allclose(pts[index], x[mine], atol=1e-6)
    red = [np.asarray(meshes["flexor"].GetDisplayColorAttr().Get(k))[0] for k in range(3)]
    assert red[0][1] > red[1][1] > red[2][1]       # greener when relaxed, deeper red when active
    bone = np.asarray(meshes["humerus"].GetDisplayColorAttr().Get(2))[0]
    np.testing.assert_allclose(bone, emu.io.plots.PART_COLOURS["bone"], atol=1e-6)


def test_emu_run_usd_streams_the_frames(tmp_path):
    from test_scenefile import GOOD, write

    scene = write(tmp_path, GOOD)
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "emu.cli", "run", str(scene), "--out", str(out), "--usd",
                        "--no-preview"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "run.usd (USD)" in r.stdout, r.stdout + r.stderr
    stage = Usd.Stage.Open(str(out / "run.usd"))
    belly = UsdGeom.Mesh(stage.GetPrimAtPath("/emu/belly"))
    assert belly.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    assert stage.GetTimeCodesPerSecond() == pytest.approx(2.0)     # dt = 0.5 s


def test_without_usd_core_the_error_says_how_to_get_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pxr", None)      # as if usd-core were not installed
    scene = emu.scenes.arm(1)
    with pytest.raises(ImportError, match=r"pip install emu\[usd\]"):
        emu.io.write_usd(tmp_path / "x.usd", scene, [scene.points])
    assert not emu.io.usd.usd_available()
