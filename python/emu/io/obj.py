"""Wavefront OBJ output of a boundary surface (for Blender); boundary_faces
lives in emu.geometry (contact uses it too)."""
from __future__ import annotations

import os

import numpy as np

from ..geometry import boundary_faces

__all__ = ["boundary_faces", "write_obj"]

def write_obj(path, points: np.ndarray, faces: np.ndarray):
    """A triangle surface as Wavefront OBJ (1-based indices), for Blender:
    points (n, 3), faces (f, 3) vertex ids; only the vertices faces use are written."""
    used = np.unique(faces)
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    with open(os.fspath(path), "w") as f:
        f.write("# emu surface\n")
        np.savetxt(f, points[used], fmt="v %.9g %.9g %.9g")
        np.savetxt(f, remap[faces] + 1, fmt="f %d %d %d")
