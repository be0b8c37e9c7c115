"""Joints between bones: detected where two bones share vertices, or declared
where they do not touch.

One shared vertex is a ball joint (it turns about that point), two or more on
one line a hinge (it turns about that line), more not on a line a weld (the
bones cannot move against each other). A declared joint is a ball joint at a
given centre, or with an axis a hinge about the line through it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .geometry import bbox_diagonal, tet_vertices

__all__ = ["Joint", "JOINT_KINDS", "joint_kind", "detect_joints", "declare_joint"]

JOINT_KINDS = ("ball", "hinge", "weld")


@dataclass(eq=False)
class Joint:
    """A joint between two bones.

    bones     the two bone names
    kind      "ball", "hinge" or "weld"
    centre    (3,) the ball centre, or a point on the hinge axis (detected: the
              mean of the shared vertices)
    axis      (3,) unit hinge axis, or None (ball, weld)
    vertices  (k,) ids of the vertices the bones share (empty for a declared joint)
    declared  True for a joint given with Scene.add_joint, False for a detected one
    """
    bones: tuple
    kind: str
    centre: np.ndarray
    axis: np.ndarray | None = None
    vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    declared: bool = False


def joint_kind(p: np.ndarray, diag: float) -> tuple:
    """("ball" | "hinge" | "weld", unit axis (3,) or None) of shared joint
    vertices p (k, 3); diag is the scene's bounding-box diagonal (the scale of
    the collinearity test). A hinge axis points along its largest component's
    positive direction."""
    if len(p) == 1:
        return "ball", None
    c = p - p.mean(axis=0)
    _, sv, vt = np.linalg.svd(c, full_matrices=False)
    if len(sv) > 1 and sv[1] > 1e-6 * diag:
        return "weld", None
    return "hinge", vt[0] * (1.0 if vt[0][np.argmax(np.abs(vt[0]))] > 0 else -1.0)


def detect_joints(points: np.ndarray, tets: np.ndarray, bones: dict) -> list:
    """Joints where two bones share vertices.

    points  (n, 3) rest positions; tets  (m, 4) vertex ids
    bones   {bone name: tet ids} in the scene's order
    Returns one Joint per pair of bones that share at least one vertex.
    """
    names = list(bones)
    verts = {name: tet_vertices(tets[bones[name]], len(points)) for name in names}
    diag = bbox_diagonal(points)
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            shared = np.intersect1d(verts[a], verts[b])
            if len(shared) == 0:
                continue
            p = points[shared]
            kind, axis = joint_kind(p, diag)
            out.append(Joint(bones=(a, b), kind=kind, centre=p.mean(axis=0), axis=axis, vertices=shared))
    return out


def declare_joint(bone_names, bone: str, other: str, centre, axis=None) -> Joint:
    """A declared Joint between ``bone`` and ``other``, both in ``bone_names``:
    a ball joint at ``centre`` (3,), or with ``axis`` (3,) a hinge about the line
    through it. Raises ValueError naming the problem."""
    known = list(bone_names)
    for name in (bone, other):
        if name not in known:
            raise ValueError(f"add_joint: no bone named {name!r} (bones: {', '.join(known) or 'none'}); "
                             "add the bones first")
    if bone == other:
        raise ValueError(f"add_joint: a joint needs two different bones, got {bone!r} twice")
    c = np.asarray(centre, dtype=np.float64)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"add_joint: centre must be a finite 3-vector, got {centre!r}")
    a = None
    if axis is not None:
        a = np.asarray(axis, dtype=np.float64)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
            raise ValueError(f"add_joint: axis must be a non-zero finite 3-vector, got {axis!r}")
        a = a / np.linalg.norm(a)
    return Joint(bones=(bone, other), kind="ball" if a is None else "hinge", centre=c, axis=a, declared=True)
