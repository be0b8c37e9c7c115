"""Measuring bones in a solution: the rigid motion that best explains where a
bone's vertices went, its turn about an axis, and how rigid it stayed."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.geometry import bbox_diagonal, rigid_fit, tet_vertices

__all__ = ["BoneMotion", "rigid_fit", "bone_motion", "signed_angle", "bone_angle"]


@dataclass
class BoneMotion:
    R: np.ndarray        # (3, 3) rotation
    t: np.ndarray        # (3,) translation: x = R X + t
    angle_deg: float     # rotation angle (unsigned)
    rigidity: float      # largest vertex distance from the rigid fit / bone's bounding-box diagonal


def bone_motion(scene, positions, bone: str) -> BoneMotion:
    """The rigid motion of ``bone`` from rest to ``positions`` ((n, 3) or a Solution)."""
    part = scene.parts.get(bone)
    if part is None or part.kind != "bone":
        bones = [p.name for p in scene.parts.values() if p.kind == "bone"]
        raise ValueError(f"no bone named {bone!r} (bones: {', '.join(bones) or 'none'})")
    P = np.asarray(getattr(positions, "positions", positions))
    v = tet_vertices(scene.tets[part.tets], len(scene.points))
    X, Y = scene.points[v], P[v]
    R, t = rigid_fit(X, Y)
    diag = bbox_diagonal(X)
    rig = float(np.linalg.norm(X @ R.T + t - Y, axis=1).max() / diag)
    ang = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return BoneMotion(R=R, t=t, angle_deg=ang, rigidity=rig)


def signed_angle(R: np.ndarray, axis) -> float:
    """The turn of rotation R about ``axis`` in degrees (right-hand rule), from
    its rotation vector projected on the axis."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    ang = np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    n = np.linalg.norm(w)
    if n < 1e-15:
        return float(np.degrees(ang)) if ang < 1.0 else 180.0
    return float(np.degrees(ang) * (w / n) @ a)


def own_joint(scene, bone: str):
    """The joint that holds ``bone`` to the rest of the skeleton: the one
    through which a walk of the joints from the fixed (and scripted) bones
    first reaches it (the humerus' shoulder, not the elbow its forearm hangs
    on); None for a bone no joint reaches."""
    joints = [j for j in scene.joints() if j.kind in ("hinge", "ball")]
    fixed = [n for n, p in scene.parts.items() if p.kind == "bone" and p.fixed]
    reached, frontier = set(fixed), list(fixed)
    while frontier:
        nxt = []
        for j in joints:
            a, b = j.bones
            for here, there in ((a, b), (b, a)):
                if here in frontier and there not in reached:
                    if there == bone:
                        return j
                    reached.add(there)
                    nxt.append(there)
        frontier = nxt
    return None


def bone_angle(scene, positions, bone: str) -> float:
    """A bone's turn in degrees: signed about its own joint's axis (own_joint)
    where that joint is a hinge, else the unsigned rotation angle."""
    bm = bone_motion(scene, positions, bone)
    j = own_joint(scene, bone)
    if j is not None and j.kind == "hinge":
        return signed_angle(bm.R, j.axis)
    return bm.angle_deg
