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


def _volumes(x, tets):
    a, b, c, d = (x[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def test_a_stage_holds_every_part_at_every_frame(tmp_path):
    """Bones as rigid transforms over their rest surface, soft parts as meshes
    with per-face activation, J and fibre primvars and as tet meshes, every
    one time-sampled per frame; read back with Pixar's library."""
    scene = emu.scenes.arm(1)
    solver = emu.Solver(scene, "fem")
    acts = [{"flexor": a} for a in (0.0, 0.3, 0.6)]
    frames = [solver.solve(a, normalized=True).positions for a in acts]
    path = emu.io.write_usd(tmp_path / "arm.usda", scene, frames, dt=0.25, activations=acts, meters_per_unit=0.01)
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == pytest.approx(4.0)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 2)
    assert stage.GetDefaultPrim().GetPath() == "/emu"
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
    rest_volume = _volumes(scene.points, scene.tets)
    for name, part in scene.parts.items():
        mine = np.isin(faces_tet, part.tets)
        if part.kind == "bone":
            xform = UsdGeom.Xform(stage.GetPrimAtPath(f"/emu/{name}"))
            mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/emu/{name}/surface"))
            assert xform and mesh and mesh.GetPointsAttr().GetTimeSamples() == []      # a rigid body
            rest = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
            index = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
            for k, x in enumerate(frames):
                M = np.asarray(xform.GetLocalTransformation(k))           # row vectors: x' = x M
                moved = rest @ M[:3, :3] + M[3, :3]
                np.testing.assert_allclose(moved[index], x[faces[mine]], atol=1e-6)
            continue
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/emu/{name}"))
        index = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        assert len(index) == mine.sum() and mesh.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
        pv = UsdGeom.PrimvarsAPI(mesh)
        tm = UsdGeom.TetMesh(stage.GetPrimAtPath(f"/emu/tets/{name}"))
        tet_index = np.asarray(tm.GetTetVertexIndicesAttr().Get())
        assert tet_index.shape == (len(part.tets), 4)
        for k, x in enumerate(frames):
            pts = np.asarray(mesh.GetPointsAttr().Get(k), dtype=np.float64)
            np.testing.assert_allclose(pts[index], x[faces[mine]], atol=1e-6)
            J = (_volumes(x, scene.tets) / rest_volume)[faces_tet[mine]]
            np.testing.assert_allclose(np.asarray(pv.GetPrimvar("emu:J").Get(k)), J, rtol=1e-5)
            a = acts[k].get(name, 0.0)
            np.testing.assert_allclose(np.asarray(pv.GetPrimvar("emu:activation").Get(k)), a, atol=1e-7)
            fib = np.asarray(pv.GetPrimvar("emu:fiber").Get(k))
            assert fib.shape == (mine.sum(), 3)
            np.testing.assert_allclose(np.linalg.norm(fib, axis=1), 1.0 if part.kind == "muscle" else 0.0,
                                       atol=1e-6)
            tpts = np.asarray(tm.GetPointsAttr().Get(k), dtype=np.float64)
            np.testing.assert_allclose(tpts[tet_index], x[scene.tets[part.tets]], atol=1e-6)
    flexor = UsdGeom.Mesh(stage.GetPrimAtPath("/emu/flexor"))
    red = [np.asarray(flexor.GetDisplayColorAttr().Get(k))[0] for k in range(3)]
    assert red[0][1] > red[1][1] > red[2][1]       # greener when relaxed, deeper red when active
    with pytest.raises(ValueError, match="meters_per_unit must be a positive number"):
        emu.io.write_usd(tmp_path / "bad.usda", scene, frames, meters_per_unit=0)


def test_emu_run_usd_streams_the_frames(tmp_path):
    from test_scenefile import GOOD, write

    scene = write(tmp_path, GOOD + "\n[output]\nmeters_per_unit = 0.001\n")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "emu", "run", str(scene), "--out", str(out), "--usd",
                        "--no-preview"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "run.usd (USD)" in r.stdout, r.stdout + r.stderr
    stage = Usd.Stage.Open(str(out / "run.usd"))
    belly = UsdGeom.Mesh(stage.GetPrimAtPath("/emu/belly"))
    assert belly.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    assert stage.GetTimeCodesPerSecond() == pytest.approx(2.0)     # dt = 0.5 s
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.001)
    assert UsdGeom.PrimvarsAPI(belly).GetPrimvar("emu:activation").GetTimeSamples() == [0.0, 1.0, 2.0]


def test_without_usd_core_the_error_says_how_to_get_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pxr", None)      # as if usd-core were not installed
    scene = emu.scenes.arm(1)
    with pytest.raises(ImportError, match=r"pip install emu\[usd\]"):
        emu.io.write_usd(tmp_path / "x.usd", scene, [scene.points])
    assert not emu.io.usd.usd_available()


def test_a_time_step_run_writes_the_soft_meshes_velocities(tmp_path):
    """emu.Dynamics time steps: each soft mesh's velocities attribute holds the
    step's vertex velocities at its time code (motion blur in renderers)."""
    scene = emu.scenes.fusiform(2, warn=False)
    solver = emu.Solver(scene, "fem")
    sols = list(emu.solve_frames(solver, [{"belly": 4e4}] * 2, dynamics=emu.Dynamics(0.1)))
    writer = emu.io.usd.UsdWriter(str(tmp_path / "steps.usda"), scene, 0.1)
    for k, sol in enumerate(sols):
        writer.add_frame(k, sol.positions, velocities=sol.velocities)
    writer.save()
    stage = Usd.Stage.Open(str(tmp_path / "steps.usda"))
    faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
    checked = 0
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        for k, sol in enumerate(sols):
            p = np.array(mesh.GetPointsAttr().Get(k))
            v = np.array(mesh.GetVelocitiesAttr().Get(k))
            assert v.shape == p.shape
            # each mesh point is a scene vertex: its velocity is that vertex's
            rows = [int(np.argmin(np.linalg.norm(sol.positions - q, axis=1))) for q in p]
            assert np.allclose(v, sol.velocities[rows], rtol=1e-5, atol=1e-6 * np.abs(sol.velocities).max())
            checked += 1
    assert checked == 2 * len([p for p in scene.parts.values() if p.kind != "bone"])
