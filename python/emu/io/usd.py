"""Animated surfaces as USD (OpenUSD, the ``usd-core`` package): one stage per
run, one Mesh prim per part under ``/emu``, each part's surface points as a
time sample per frame; muscles' display colour follows their activation.
usdview, Blender, Houdini, Maya and Omniverse open it.

``usd-core`` is an optional extra (``pip install emu[usd]``): the stage is
written by Pixar's own library, so every USD reader takes it, and nothing
else of emu needs it.
"""
from __future__ import annotations

import os

import numpy as np

from ..geometry import boundary_faces
from .obj import part_groups
from .plots import PART_COLOURS, default_view, muscle_colour

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
    """

    def __init__(self, path, scene, dt: float = 1.0, up: str | None = None):
        Gf, Sdf, Tf, Usd, UsdGeom, Vt = _pxr()
        self._gf, self._vt, self._usdgeom = Gf, Vt, UsdGeom
        self.path = os.fspath(path)
        self.scene = scene
        if os.path.exists(self.path):
            os.remove(self.path)          # a rerun replaces the stage, never layers onto it
        self.stage = Usd.Stage.CreateNew(self.path)
        if up is None:
            up = "z" if default_view(scene)[1] == 2 else "y"
        if up not in ("y", "z"):
            raise ValueError(f"up must be 'y' or 'z' (USD's up axes), got {up!r}")
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.z if up == "z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        if dt > 0:
            self.stage.SetTimeCodesPerSecond(1.0 / dt)
            self.stage.SetFramesPerSecond(1.0 / dt)
        root = UsdGeom.Xform.Define(self.stage, ROOT)
        self.stage.SetDefaultPrim(root.GetPrim())
        faces, faces_tet = boundary_faces(scene.tets, return_tets=True)
        self._parts = []     # (part, Mesh, local vertex ids (k,))
        used_names = set()
        for name, ids in part_groups(scene, faces_tet):
            part = scene.parts.get(name)
            prim_name = Tf.MakeValidIdentifier(name)
            while prim_name in used_names:
                prim_name += "_"
            used_names.add(prim_name)
            f = faces[ids]
            verts, local = np.unique(f, return_inverse=True)
            mesh = UsdGeom.Mesh.Define(self.stage, f"{ROOT}/{prim_name}")
            mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(f)))
            mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(local.reshape(-1).astype(int).tolist()))
            mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)   # boundary faces turn outward
            mesh.GetPrim().SetCustomDataByKey("emu:part", name)
            mesh.GetPrim().SetCustomDataByKey("emu:kind", part.kind if part else "unlabelled")
            colour = PART_COLOURS.get(part.kind if part else "bone", (0.7, 0.7, 0.7))
            mesh.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(*colour)]))
            self._parts.append((part, mesh, verts))
        self.frames = 0

    def add_frame(self, frame: int, positions, activation: dict | None = None) -> None:
        """The surfaces at time code ``frame``: positions (n, 3) of every mesh
        vertex; activation {muscle: normalised a} colours the muscles."""
        Gf, Vt = self._gf, self._vt
        x = np.asarray(positions, dtype=np.float64)
        for part, mesh, verts in self._parts:
            p = x[verts]
            mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), frame)
            lo, hi = p.min(axis=0), p.max(axis=0)
            mesh.GetExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*lo.tolist()), Gf.Vec3f(*hi.tolist())]), frame)
            if activation is not None and part is not None and part.kind == "muscle":
                colour = muscle_colour(float(activation.get(part.name, 0.0)))
                mesh.GetDisplayColorAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*colour)]), frame)
        self.stage.SetStartTimeCode(0)
        self.stage.SetEndTimeCode(max(frame, self.stage.GetEndTimeCode()))
        self.frames += 1

    def save(self) -> str:
        self.stage.GetRootLayer().Save()
        return self.path


def write_usd(path, scene, frames, *, dt: float = 1.0, activations=None, up: str | None = None) -> str:
    """Write solved frames as one animated USD stage.

    frames       list of (n, 3) positions (or Solutions), one per frame
    dt           seconds per frame
    activations  one {muscle: normalised activation} per frame (muscle colours), or None
    Returns the path."""
    w = UsdWriter(path, scene, dt, up)
    for k, f in enumerate(frames):
        w.add_frame(k, getattr(f, "positions", f), activations[k] if activations else None)
    return w.save()
