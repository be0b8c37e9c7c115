"""Small geometric measures in numpy: the bounding-box diagonal every relative
tolerance and error is measured against, vertex errors, per-tet deformation
gradients (for output, not for solving)."""
from __future__ import annotations

import numpy as np

from .. import _core

__all__ = ["rigid_fit", "error_history", "time_to_error", "time_within", "bbox_diagonal", "vertex_error", "deformation_gradients",
           "boundary_faces", "tet_vertices"]


def tet_vertices(tets, num_vertices: int) -> np.ndarray:
    """Sorted ids of the vertices of ``tets`` (k, 4) ids in [0, num_vertices):
    np.unique of them, by a mask (np.unique sorts, which is much slower)."""
    mask = np.zeros(num_vertices, bool)
    mask[np.asarray(tets).ravel()] = True
    return np.flatnonzero(mask)


def bbox_diagonal(points) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``points`` (n, 3)."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"bbox_diagonal needs a non-empty (n, 3) point array, got shape {p.shape}")
    # over a contiguous (3, n) copy: numpy reduces an (n, 3) array along axis 0
    # row by row, far slower (and it is called several times per solve)
    q = np.ascontiguousarray(p.T)
    return float(np.linalg.norm(q.max(axis=1) - q.min(axis=1)))


def vertex_error(a, b, points=None) -> float:
    """Largest vertex distance between two (n, 3) position arrays (or Solutions),
    relative to the bounding-box diagonal of ``points`` (n, 3) (default: of ``b``)."""
    pa = np.asarray(getattr(a, "positions", a))
    pb = np.asarray(getattr(b, "positions", b))
    if pa.shape != pb.shape:
        raise ValueError(f"position arrays differ in shape: {pa.shape} vs {pb.shape}")
    diag = bbox_diagonal(pb if points is None else points)
    return float(np.linalg.norm(pa - pb, axis=1).max() / diag)


def error_history(solution, reference, points=None) -> tuple:
    """Error against run time of one solve: (time_s (k,), error (k,)) with the
    vertex_error of every recorded iterate of ``solution`` (solved with
    record_iterates=True) to ``reference`` ((n, 3) or a Solution, typically the
    converged FEM answer), the start first."""
    its = getattr(solution, "iterates", None)
    if not its:
        raise ValueError("the solution has no recorded iterates: solve with record_iterates=True")
    ref = np.asarray(getattr(reference, "positions", reference))
    pts = ref if points is None else points
    t = np.array([ti for ti, _ in its])
    e = np.array([vertex_error(x, ref, pts) for _, x in its])
    return t, e


def time_to_error(solution, reference, target: float, points=None) -> float:
    """The solve time at which ``solution``'s iterates first come within
    ``target`` vertex error of ``reference`` (and stay there); inf if never."""
    return time_within(*error_history(solution, reference, points), target)


def time_within(t, e, target: float) -> float:
    """The first time of an error curve (t, e: (k,) arrays, t increasing) from
    which every error is within ``target``; inf if the last one is not."""
    t, e = np.asarray(t, float), np.asarray(e, float)
    above = np.flatnonzero(e > target)
    if len(above) == 0:
        return float(t[0])
    return float(t[above[-1] + 1]) if above[-1] + 1 < len(t) else float("inf")


def deformation_gradients(rest: np.ndarray, tets: np.ndarray, x: np.ndarray) -> np.ndarray:
    """F_t = D_s D_m^-1 for every tet: rest, x (n, 3); tets (m, 4) -> (m, 3, 3)."""
    def edges(p):
        q = p[tets]
        return np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]], axis=2)
    return edges(x) @ np.linalg.inv(edges(rest))


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


def rigid_fit(X: np.ndarray, Y: np.ndarray) -> tuple:
    """(R, t) minimising sum |R X_i + t - Y_i|^2 over rotations (Kabsch).

    X, Y  (n, 3) matching point sets, n >= 3 not collinear for a unique R
    """
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    if X.shape != Y.shape or X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"need two (n, 3) point arrays of equal shape, got {X.shape} and {Y.shape}")
    if len(X) == 0:
        raise ValueError("need at least one point to fit a rigid motion")
    # the same Kabsch fit the FEM solver starts its rigid bones with (linalg/rotation.h)
    R = np.asarray(_core.best_rotation(X, Y))
    return R, Y.mean(axis=0) - R @ X.mean(axis=0)
