"""Boundary surface of a tet mesh and Wavefront OBJ output (for Blender)."""
from __future__ import annotations

import os

import numpy as np

__all__ = ["boundary_faces", "write_obj"]

# outward faces of a positively oriented tet (a, b, c, d)
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def boundary_faces(tets: np.ndarray, return_tets: bool = False):
    """Triangles of tets (m, 4) that belong to exactly one tet, outward-oriented:
    (f, 3) vertex ids (and, with return_tets, the tet of each: (f,))."""
    faces = tets[:, _FACES].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    on = counts[inverse.ravel()] == 1
    if return_tets:
        return faces[on], np.repeat(np.arange(len(tets)), 4)[on]
    return faces[on]


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
