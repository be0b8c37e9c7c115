"""Wavefront OBJ output of a boundary surface (for Blender); boundary_faces
lives in emu.geometry (contact uses it too)."""
from __future__ import annotations

import os

import numpy as np

from ..core.geometry import boundary_faces

__all__ = ["boundary_faces", "write_obj", "part_groups"]

def write_obj(path, points: np.ndarray, faces: np.ndarray, groups=None):
    """A triangle surface as Wavefront OBJ (1-based indices), for Blender:
    points (n, 3), faces (f, 3) vertex ids; only the vertices faces use are written.
    groups  [(name, face ids)]: each listed as its own object and group
            (``o name`` / ``g name``), so Blender and Houdini import one
            object per part; None: one unnamed surface."""
    used = np.unique(faces)
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    with open(os.fspath(path), "w") as f:
        f.write("# emu surface\n")
        np.savetxt(f, points[used], fmt="v %.9g %.9g %.9g")
        if groups is None:
            np.savetxt(f, remap[faces] + 1, fmt="f %d %d %d")
            return
        for name, ids in groups:
            name = "_".join(str(name).split()) or "part"   # OBJ names end at whitespace
            f.write(f"o {name}\ng {name}\n")
            np.savetxt(f, remap[faces[np.asarray(ids, np.int64)]] + 1, fmt="f %d %d %d")


def part_groups(scene, faces_tet: np.ndarray) -> list:
    """[(part name, face ids)] for write_obj: each boundary face (faces_tet: its
    tet, (f,)) goes to the part of its tet; parts with no boundary face are left out."""
    face_part = scene.part_index[faces_tet]
    out = [(p.name, np.flatnonzero(face_part == k)) for k, p in enumerate(scene.parts.values())]
    rest = np.flatnonzero(face_part < 0)
    if len(rest):
        out.append(("unlabelled", rest))
    return [(n, ids) for n, ids in out if len(ids)]
