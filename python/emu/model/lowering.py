"""Lowering a Scene to the flat per-tet arrays of the C++ model (_core.Model).

A pure function of the scene: nothing here writes into it. Muscles without
fibres get their Laplace field between their two bone attachments computed for
the model (Scene.resolve_fibers stores the same fields in the scene, if wanted).
"""
from __future__ import annotations

import numpy as np

from .. import _core
from ..core.fibers import attachment_fibers
from ..core.geometry import bbox_diagonal
from .parts import lame

__all__ = ["build_model", "tet_fibers", "declared_joint_rows", "declared_joint_world"]


def tet_fibers(scene) -> np.ndarray:
    """Rest fibre direction of every tet of the scene (m, 3): the muscles' own
    fibres, a Laplace field between the two bone attachments of a muscle that
    has none (computed, not stored), zero on tendons and bones."""
    fib = np.zeros((len(scene.tets), 3))
    for p in scene.parts.values():
        if p.kind != "muscle":
            continue
        fib[p.tets] = p.fibers if p.fibers is not None else \
            attachment_fibers(scene.points, scene.tets, p.name, p.tets, scene.attachments(p.name))
    return fib


def declared_joint_rows(scene) -> tuple:
    """Rest points (r, 3) and (movable bone index, other movable bone index or -1)
    pairs (r, 2) of the scene's declared joints: one row per ball joint, two per
    hinge (points a tenth of the diagonal either side of the centre on the axis)."""
    movable = scene.movable_bones
    diag = bbox_diagonal(scene.points)
    pts, pairs = [], []
    for j in scene.declared_joints:
        a, b = j.bones
        if a not in movable:
            a, b = b, a
        if a not in movable:
            raise ValueError(f"joint {j.bones}: both bones are fixed; make one of them movable "
                             "(fixed=False) or drop the joint")
        ib = movable.index(b) if b in movable else -1
        rows = [j.centre] if j.axis is None else [j.centre - 0.1 * diag * j.axis, j.centre + 0.1 * diag * j.axis]
        for p in rows:
            pts.append(p)
            pairs.append((movable.index(a), ib))
    return np.asarray(pts, float).reshape(-1, 3), np.asarray(pairs, np.int64).reshape(-1, 2)


def declared_joint_world(scene) -> list:
    """(row, fixed bone name) of every declared-joint row (see declared_joint_rows)
    tied to a fixed bone: the rows a scripted bone carries with it."""
    movable = scene.movable_bones
    out, row = [], 0
    for j in scene.declared_joints:
        a, b = j.bones
        if a not in movable:
            a, b = b, a
        n = 1 if j.axis is None else 2
        if b not in movable:
            out += [(row + i, b) for i in range(n)]
        row += n
    return out


def build_model(scene, fibers=None) -> "_core.Model":
    """The flat arrays the C++ solvers take (tets of fixed bones left out), after
    scene.validate(). The scene is not changed. The model's tet t is the
    scene's tet model.scene_tet[t] (scene.model_tets, in the scene's order; a
    solver stores them in an order of its own and gives F back per scene tet).

    fibers  (m, 3) rest fibre directions per tet of the scene, as from
            tet_fibers(scene) (None: computed here)
    """
    scene.validate()
    fib = tet_fibers(scene) if fibers is None else np.asarray(fibers, dtype=np.float64)
    if fib.shape != (len(scene.tets), 3):
        raise ValueError(f"build_model: fibers must have shape ({len(scene.tets)}, 3), got {fib.shape}")
    keep = scene.model_tets
    m = len(scene.tets)
    mu, lam, rho, w = (np.empty(m) for _ in range(4))
    muscle = np.full(m, -1, np.int32)
    bone = np.full(m, -1, np.int32)
    names = scene.muscles
    movable = scene.movable_bones
    for p in scene.parts.values():
        if p.kind == "bone" and not p.fixed:
            bone[p.tets] = movable.index(p.name)
        pm, pl = lame(p.youngs, p.poisson)
        mu[p.tets], lam[p.tets], rho[p.tets] = pm, pl, p.density
        w[p.tets] = scene.acap_weight_of(p)
        if p.kind == "muscle":
            muscle[p.tets] = names.index(p.name)
    model = _core.Model()
    model.rest = scene.points
    model.tets = scene.tets[keep].astype(np.int32)
    model.mu, model.lam, model.density, model.acap_weight = mu[keep], lam[keep], rho[keep], w[keep]
    model.fiber = fib[keep]
    model.muscle = muscle[keep]
    model.scene_tet = keep.astype(np.int32)
    model.num_scene_tets = len(scene.tets)
    model.pinned = scene.model_pins()[0].astype(np.int32)
    model.num_muscles = len(names)
    if movable:
        model.bone = bone[keep]
        model.num_bones = len(movable)
        k = np.array([scene.parts[n].joint_stiffness for n in movable], float)
        if np.any(k > 0):
            model.bone_stiffness = k
    pts, pairs = declared_joint_rows(scene)
    if len(pts):
        model.joint_points = pts
        model.joint_bones = pairs.astype(np.int32)
    return model
