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

from ..core.geometry import bbox_diagonal, tet_vertices

__all__ = ["Joint", "JOINT_KINDS", "joint_kind", "detect_joints", "declare_joint", "check_declared_joints",
           "joint_loop", "loop_note"]

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


def check_declared_joints(points: np.ndarray, tets: np.ndarray, detected: list, declared: list) -> None:
    """Raise ValueError where two bones joined by a declared joint also share
    vertices: the mesh fused them where their surfaces come close (a mesher
    merges surfaces nearer than its edge length), which would be a second
    joint beside the declared one, or a weld.

    points    (n, 3) rest positions; tets  (m, 4) vertex ids
    detected  the joints detect_joints found; declared  the declared ones
    The message names both bones, where they touch, and the gap the mesh
    needs there (the longest edge of the tets at the shared vertices).
    """
    pairs = {frozenset(j.bones): j for j in declared}
    for j in detected:
        mine = pairs.get(frozenset(j.bones))
        if mine is None:
            continue
        at = np.isin(tets, j.vertices).any(axis=1)
        t = tets[at]
        edges = np.concatenate([points[t[:, a]] - points[t[:, b]] for a, b in
                                ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
        gap = float(np.sqrt((edges ** 2).sum(axis=1).max()))
        where = ", ".join(f"{v:.4g}" for v in j.centre)
        what = {"weld": "welds them (the bones cannot move)", "hinge": "is a second hinge",
                "ball": "is a second (ball) joint"}[j.kind]
        raise ValueError(
            f"bones '{j.bones[0]}' and '{j.bones[1]}' share {len(j.vertices)} vertex/vertices near "
            f"[{where}] beside their declared {mine.kind} joint: the mesh fused them where their surfaces come "
            f"close, which {what}. Move the surfaces at least {gap:.3g} apart there (the mesh's edge length), "
            "e.g. a pose with the joint more open, or a finer mesh; or drop the declared joint to use the "
            "touching vertices as the joint")


def joint_loop(joints: list, movable) -> tuple | None:
    """The first joint that closes a loop (two bones already joined through
    other joints, fixed bones counting as one ground), as (bone, other), or
    None where the joints form trees. FEM, and with it EMU's error estimate,
    takes trees of bones only (the solvers also count pins and fixed bones a
    bone touches, which this graph of joints leaves out).

    joints   Joint list (Scene.joints())
    movable  names of the movable bones
    """
    movable = set(movable)
    parent = {}

    def root(n):
        n = n if n in movable else "<ground>"
        while parent.get(n, n) != n:
            n = parent[n]
        return n
    for j in joints:
        a, b = j.bones
        if a not in movable and b not in movable:
            continue
        ra, rb = root(a), root(b)
        if ra == rb:
            return a, b
        parent[ra] = rb
    return None


def loop_note(pair: tuple) -> str:
    """What a loop of joints (joint_loop's pair) means for the solvers, and the fixes."""
    a, b = pair
    return (f"bones '{a}' and '{b}' close a loop of joints: FEM and EMU's accuracy mode (its error estimate is "
            "FEM's) refuse it; fix a bone of the loop, remove a joint (two touching bones moved as one: make "
            "them one bone), or solve with EMU at a given alpha= without an estimate of its error")
