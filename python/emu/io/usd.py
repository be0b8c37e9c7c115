"""A run as USD (OpenUSD, the ``usd-core`` package), for production tools:
usdview, Blender, Houdini, Maya and Omniverse open it.

Under ``/emu`` (the default prim), one prim per part:
- a bone is an Xform whose ``xformOp:transform`` is time-sampled per frame
  (its rigid motion, x = R X + t, fitted to its vertices) over a Mesh
  ``surface`` of its rest surface: a rigid body, as animators rig bones;
- a soft part (muscle, tendon) is a Mesh whose points are time-sampled, with
  per-face primvars ``emu:activation`` (the normalised activation),
  ``emu:J`` (volume ratio) and ``emu:fiber`` (deformed unit fibre), each
  face carrying its tet's value, time-sampled; muscles' display colour
  follows their activation;
- ``/emu/tets/<part>``: each soft part's tets as a UsdGeom.TetMesh (where
  usd-core has it), points time-sampled, for tools that simulate or render
  volumes.
Time codes are frame numbers at timeCodesPerSecond = framesPerSecond = 1 / dt;
metersPerUnit says what one scene unit is (1 for the built-in anatomy and
arm26, which are in metres; the authors' research scenes are in
unspecified units).

``usd-core`` is an optional extra (``pip install emu[usd]``): the stage is
written by Pixar's own library, so every USD reader takes it, and nothing
else of emu needs it.
"""
from __future__ import annotations

import os

import numpy as np

from ..core.geometry import boundary_faces, rigid_fit
from .obj import part_groups
from .plots import PART_COLOURS, default_view, muscle_colour
from .vtk import tet_fields

__all__ = ["UsdWriter", "write_usd", "usd_available"]

ROOT = "/emu"


def _pxr():
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, Vt
    except ImportError:
        raise ImportError("USD output needs the usd-core package: pip install emu[usd] "
                          "(or pip install usd-core)") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, Vt


def usd_available() -> bool:
    """Whether usd-core is installed (USD output works)."""
    try:
        _pxr()
    except ImportError:
        return False
    return True


class UsdWriter:
    """A USD stage written frame by frame (emu run streams into it).

    path    the file (.usd or .usdc: binary; .usda: text)
    scene   the emu.Scene whose parts become prims
    dt      seconds per frame (the stage's time codes are frame numbers,
            timeCodesPerSecond = 1 / dt)
    up      "y" or "z": the stage's up axis (None: the up of default_view, the
            picture emu draws; USD has no x-up); positions are written as they are
    meters_per_unit  what one scene unit is, in metres (the stage's metersPerUnit)
    fibers  (m, 3) rest fibre per tet for the emu:fiber primvar (a Solver's
            ``fibers``); None: the scene's
    tets    also write each soft part as a UsdGeom.TetMesh (where usd-core has it)
    """

    def __init__(self, path, scene, dt: float = 1.0, up: str | None = None, *, meters_per_unit: float = 1.0,
                 fibers=None, tets: bool = True):
        Gf, Sdf, Tf, Usd, UsdGeom, Vt = _pxr()
        self._gf, self._vt, self._usdgeom, self._sdf = Gf, Vt, UsdGeom, Sdf
        if not (isinstance(meters_per_unit, (int, float)) and meters_per_unit > 0):
            raise ValueError(f"meters_per_unit must be a positive number, got {meters_per_unit!r}")
        self.path = os.fspath(path)
        self.scene = scene
        self.fibers = fibers
        if os.path.exists(self.path):
            os.remove(self.path)          # a rerun replaces the stage, never layers onto it
        self.stage = Usd.Stage.CreateNew(self.path)
        if up is None:
            up = "z" if default_view(scene)[1] == 2 else "y"
        if up not in ("y", "z"):
            raise ValueError(f"up must be 'y' or 'z' (USD's up axes), got {up!r}")
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.z if up == "z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, float(meters_per_unit))
        if dt > 0:
            self.stage.SetTimeCodesPerSecond(1.0 / dt)
            self.stage.SetFramesPerSecond(1.0 / dt)
        root = UsdGeom.Xform.Define(self.stage, ROOT)
        self.stage.SetDefaultPrim(root.GetPrim())
        faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
        self._bones, self._soft, self._tetmeshes = [], [], []
        used_names = set()
        for name, ids in part_groups(scene, faces_tet):
            part = scene.parts.get(name)
            prim_name = Tf.MakeValidIdentifier(name)
            while prim_name in used_names:
                prim_name += "_"
            used_names.add(prim_name)
            f = faces[ids]
            verts, local = np.unique(f, return_inverse=True)
            kind = part.kind if part else "unlabelled"
            if kind == "bone":
                xform = UsdGeom.Xform.Define(self.stage, f"{ROOT}/{prim_name}")
                op = xform.AddTransformOp()
                mesh = self._mesh(f"{ROOT}/{prim_name}/surface", local, name, kind)
                rest = scene.points[verts]
                mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(rest.astype(np.float32)))
                mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*rest.min(axis=0).tolist()),
                                                     Gf.Vec3f(*rest.max(axis=0).tolist())]))
                bone_verts = np.unique(scene.tets[part.tets])
                self._bones.append((part, op, bone_verts))
            else:
                mesh = self._mesh(f"{ROOT}/{prim_name}", local, name, kind)
                self._soft.append((part, mesh, verts, faces_tet[ids]))
                if tets and part is not None and hasattr(UsdGeom, "TetMesh"):
                    UsdGeom.Scope.Define(self.stage, f"{ROOT}/tets")
                    self._tetmeshes.append(self._tetmesh(f"{ROOT}/tets/{prim_name}", part))
        self.frames = 0

    def _mesh(self, where, local, name, kind):
        Gf, Vt, UsdGeom = self._gf, self._vt, self._usdgeom
        mesh = UsdGeom.Mesh.Define(self.stage, where)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * (local.size // 3)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(local.reshape(-1).astype(int).tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)   # boundary faces turn outward
        mesh.GetPrim().SetCustomDataByKey("emu:part", name)
        mesh.GetPrim().SetCustomDataByKey("emu:kind", kind)
        colour = PART_COLOURS.get(kind if kind in PART_COLOURS else "bone", (0.7, 0.7, 0.7))
        mesh.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(*colour)]))
        return mesh

    def _tetmesh(self, where, part):
        Vt, UsdGeom = self._vt, self._usdgeom
        t = self.scene.tets[part.tets]
        verts, local = np.unique(t, return_inverse=True)
        tm = UsdGeom.TetMesh.Define(self.stage, where)
        tm.CreateTetVertexIndicesAttr(Vt.Vec4iArray.FromNumpy(local.reshape(-1, 4).astype(np.int32)))
        tm.GetPrim().SetCustomDataByKey("emu:part", part.name)
        return tm, verts

    def add_frame(self, frame: int, positions, activation: dict | None = None, velocities=None) -> None:
        """The parts at time code ``frame``: positions (n, 3) of every mesh
        vertex; activation {muscle: normalised a} (the muscles' colour and
        emu:activation primvar); velocities (n, 3) a time step's (scene units per
        second: the soft meshes' velocities attribute, for motion blur), or None."""
        Gf, Vt, Sdf, UsdGeom = self._gf, self._vt, self._sdf, self._usdgeom
        x = np.asarray(positions, dtype=np.float64)
        for part, op, verts in self._bones:
            R, t = rigid_fit(self.scene.points[verts], x[verts])
            M = np.eye(4)
            M[:3, :3], M[3, :3] = R.T, t     # USD's row vectors: x' = x M
            op.Set(Gf.Matrix4d(M.tolist()), frame)
        fu, J = tet_fields(self.scene, x, self.fibers, "UsdWriter")
        for part, mesh, verts, face_tet in self._soft:
            p = x[verts]
            mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), frame)
            if velocities is not None:
                vel = np.asarray(velocities, dtype=np.float64)[verts]
                mesh.GetVelocitiesAttr().Set(Vt.Vec3fArray.FromNumpy(vel.astype(np.float32)), frame)
            lo, hi = p.min(axis=0), p.max(axis=0)
            mesh.GetExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*lo.tolist()), Gf.Vec3f(*hi.tolist())]), frame)
            a = float((activation or {}).get(part.name, 0.0)) if part is not None and part.kind == "muscle" else 0.0
            pv = UsdGeom.PrimvarsAPI(mesh)
            for name, type_, value in (
                    ("emu:activation", Sdf.ValueTypeNames.FloatArray, Vt.FloatArray([a] * len(face_tet))),
                    ("emu:J", Sdf.ValueTypeNames.FloatArray, Vt.FloatArray.FromNumpy(J[face_tet].astype(np.float32))),
                    ("emu:fiber", Sdf.ValueTypeNames.Vector3fArray,
                     Vt.Vec3fArray.FromNumpy(fu[face_tet].astype(np.float32)))):
                primvar = pv.GetPrimvar(name)
                if not primvar:
                    primvar = pv.CreatePrimvar(name, type_, UsdGeom.Tokens.uniform)
                primvar.Set(value, frame)
            if activation is not None and part is not None and part.kind == "muscle":
                mesh.GetDisplayColorAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*muscle_colour(a))]), frame)
        for tm, verts in self._tetmeshes:
            tm.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(x[verts].astype(np.float32)), frame)
        self.stage.SetStartTimeCode(0)
        self.stage.SetEndTimeCode(max(frame, self.stage.GetEndTimeCode()))
        self.frames += 1

    def save(self) -> str:
        self.stage.GetRootLayer().Save()
        return self.path


def write_usd(path, scene, frames, *, dt: float = 1.0, activations=None, up: str | None = None,
              meters_per_unit: float = 1.0, fibers=None, tets: bool = True) -> str:
    """Write solved frames as one animated USD stage (see UsdWriter).

    frames       list of (n, 3) positions (or Solutions), one per frame
    dt           seconds per frame
    activations  one {muscle: normalised activation} per frame (muscle colours), or None
    Returns the path."""
    w = UsdWriter(path, scene, dt, up, meters_per_unit=meters_per_unit, fibers=fibers, tets=tets)
    for k, f in enumerate(frames):
        w.add_frame(k, getattr(f, "positions", f), activations[k] if activations else None)
    return w.save()
