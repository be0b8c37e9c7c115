"""Small geometric measures in numpy: the bounding-box diagonal every relative
tolerance and error is measured against, vertex errors, per-tet deformation
gradients (for output, not for solving)."""
from __future__ import annotations

import numpy as np

__all__ = ["bbox_diagonal", "vertex_error", "deformation_gradients"]


def bbox_diagonal(points) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``points`` (n, 3)."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"bbox_diagonal needs a non-empty (n, 3) point array, got shape {p.shape}")
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


def vertex_error(a, b, points=None) -> float:
    """Largest vertex distance between two (n, 3) position arrays (or Solutions),
    relative to the bounding-box diagonal of ``points`` (n, 3) (default: of ``b``)."""
    pa = np.asarray(getattr(a, "positions", a))
    pb = np.asarray(getattr(b, "positions", b))
    if pa.shape != pb.shape:
        raise ValueError(f"position arrays differ in shape: {pa.shape} vs {pb.shape}")
    diag = bbox_diagonal(pb if points is None else points)
    return float(np.linalg.norm(pa - pb, axis=1).max() / diag)


def deformation_gradients(rest: np.ndarray, tets: np.ndarray, x: np.ndarray) -> np.ndarray:
    """F_t = D_s D_m^-1 for every tet: rest, x (n, 3); tets (m, 4) -> (m, 3, 3)."""
    def edges(p):
        q = p[tets]
        return np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]], axis=2)
    return edges(x) @ np.linalg.inv(edges(rest))
