"""Muscle fibre directions from a Laplace (harmonic) field between attachments.

Per muscle: solve the Laplace equation on the muscle's tets with value -1 on
its origin vertices and +1 on its insertion vertices; the fibre of each tet is
the normalised gradient of that field (docs/DESIGN.md, "Authoring", on
fibres). The attachments of a muscle are its vertices shared with bone tets.
"""
from __future__ import annotations

import numpy as np

from .. import _core

__all__ = ["laplace_fibers", "attachments", "attachment_fibers", "fiber_angle_degrees"]


def laplace_fibers(points, tets, origin, insertion, *, fill_flat: bool = False) -> np.ndarray:
    """points  (n, 3); tets  (k, 4) the muscle's tets; origin, insertion  vertex ids.
    Returns (k, 3) unit fibre directions pointing from origin to insertion.

    A tet whose four vertices are all fixed to one value (a muscle tet lying
    in its attachment) has no direction: an error, or with fill_flat the mean
    direction of the tets sharing its vertices."""
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    origin = np.unique(np.asarray(origin, dtype=np.int64).ravel())
    insertion = np.unique(np.asarray(insertion, dtype=np.int64).ravel())
    if len(origin) == 0 or len(insertion) == 0:
        raise ValueError("laplace_fibers needs at least one origin and one insertion vertex")
    if np.intersect1d(origin, insertion).size:
        raise ValueError("origin and insertion vertex sets overlap")
    in_muscle = np.zeros(len(points), bool)
    in_muscle[tets.ravel()] = True
    for name, ids in (("origin", origin), ("insertion", insertion)):
        if ids.min() < 0 or ids.max() >= len(points) or not in_muscle[ids].all():
            raise ValueError(f"{name} vertices must be vertices of the muscle's tets")
    fixed = np.concatenate([origin, insertion])
    values = np.concatenate([-np.ones(len(origin)), np.ones(len(insertion))])
    phi = _core.harmonic_field(points, tets.astype(np.int32), fixed.astype(np.int32), values)
    g = np.asarray(_core.tet_gradients(points, tets.astype(np.int32), phi))
    norm = np.linalg.norm(g, axis=1)
    flat = norm <= 1e-12 * norm.max()
    if np.any(flat) and not fill_flat:
        raise ValueError(f"{np.sum(flat)} tet(s) have no fibre direction (the field is "
                         "flat there: all four vertices fixed to the same value?)")
    g = g / np.where(flat, 1.0, norm)[:, None]
    while np.any(flat):   # flat tets take their neighbours' mean direction, front by front
        per_vertex = np.zeros((len(points), 3))
        np.add.at(per_vertex, tets[~flat].ravel(), np.repeat(g[~flat], 4, axis=0))
        mean = per_vertex[tets[flat]].sum(axis=1)
        ok = np.linalg.norm(mean, axis=1) > 0
        if not ok.any():
            raise ValueError(f"{np.sum(flat)} tet(s) have no fibre direction and no neighbour with one")
        idx = np.flatnonzero(flat)[ok]
        g[idx] = mean[ok] / np.linalg.norm(mean[ok], axis=1)[:, None]
        flat[idx] = False
    return g


def attachments(tets: np.ndarray, muscle_tets: np.ndarray, bones: dict) -> dict:
    """Muscle vertices shared with each bone: {bone name: vertex ids} (bones
    with no shared vertex are left out). bones: {name: tet ids}."""
    mv = np.unique(tets[muscle_tets].ravel())
    out = {}
    for name, bt in bones.items():
        shared = np.intersect1d(mv, np.unique(tets[bt].ravel()))
        if len(shared):
            out[name] = shared
    return out


def attachment_fibers(points, tets, muscle: str, muscle_tets, atts: dict) -> np.ndarray:
    """Laplace fibres (k, 3) of the muscle ``muscle`` (its k tet ids ``muscle_tets``)
    from its first bone attachment to its second. points  (n, 3); tets  (m, 4)
    all tets; atts  {bone name: vertex ids} as from ``attachments``: exactly two
    (else a ValueError that says what to pass instead)."""
    if len(atts) != 2:
        found = ", ".join(f"{k} ({len(v)} vertices)" for k, v in atts.items()) or "none"
        raise ValueError(f"muscle '{muscle}' has no fibres and {len(atts)} bone attachment(s) ({found}); "
                         "fibres from attachments need exactly two: pass fibers=, or origin= and "
                         "insertion= vertex ids")
    (_, origin), (_, insertion) = atts.items()
    # a muscle tet lying in an attachment (all four vertices on the bone) takes its neighbours' direction
    return laplace_fibers(points, np.asarray(tets)[muscle_tets], origin, insertion, fill_flat=True)


def fiber_angle_degrees(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees (k,) between fibre lines a, b (k, 3) (sign-free: a fibre
    and its reverse are the same)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0)))
