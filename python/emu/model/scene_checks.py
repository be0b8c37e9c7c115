"""The whole-scene checks of emu.model.scene.Scene: whether a scene can be
solved (validate), and where parts touch without being joined (cracks, loose
contacts). Functions of a scene; Scene's methods of the same names call them."""
from __future__ import annotations

import numpy as np

from ..core.checks import check_anchored, check_movable_bones, integer_ids
from ..core.checks import loose_contacts as _loose_contacts
from ..core.geometry import tet_vertices
from .joints import check_declared_joints, detect_joints

__all__ = ["validate", "cracks", "loose_contacts", "pin_targets"]


def _parts_of_vertices(scene, ids) -> list:
    """Names of the parts (in the scene's order) holding any of the vertices ids."""
    mark = np.zeros(len(scene.points), bool)
    mark[np.asarray(ids, np.int64)] = True
    return [p.name for p in scene.parts.values() if mark[scene.tets[p.tets]].any()]


def validate(scene):
    """Raise ValueError (with the fix) unless the scene can be solved (Scene.validate)."""
    if not scene.parts:
        raise ValueError("the scene has no parts: add_muscle/add_tendon first")
    free = np.flatnonzero(scene.part_index < 0)
    if len(free):
        raise ValueError(f"{len(free)} tet(s) belong to no part (e.g. tet {free[0]}); add them to a "
                         "muscle, tendon or bone")
    soft = scene.model_tets
    movable = set(scene.movable_bones)
    if len(soft) == sum(len(scene.parts[n].tets) for n in movable):
        raise ValueError("the scene has no muscle or tendon tets: nothing to simulate")
    pins, _ = scene.model_pins()
    # declared joints connect their bones' pieces (or anchor them, to a fixed bone)
    piece = {n: scene.tets[scene.parts[n].tets[0], 0] for n in movable}   # a vertex of each movable bone
    links, anchors = [], []
    for j in scene.declared_joints:
        a, b = j.bones
        if a in piece and b in piece:
            links.append((piece[a], piece[b]))
        elif a in piece or b in piece:
            anchors.append(piece[a] if a in piece else piece[b])
    bodies = [np.unique(scene.tets[scene.parts[n].tets]) for n in movable]   # a bone of several shells is one
    check_anchored(len(scene.points), scene.tets[soft], pins, links, anchors,
                   vertex_parts=lambda ids: _parts_of_vertices(scene, ids), bodies=bodies)
    if scene.declared_joints:   # a joint the mesh made beside a declared one
        check_declared_joints(scene.points, scene.tets, detect_joints(scene.points, scene.tets, scene.bone_tets()),
                              scene.declared_joints)
    check_movable_bones(scene.points, {n: tet_vertices(scene.tets[scene.parts[n].tets], len(scene.points))
                                      for n in scene.movable_bones}, pins)
    if not np.all(np.isfinite(scene.gravity)) or np.shape(scene.gravity) != (3,):
        raise ValueError(f"gravity must be a finite 3-vector, got {scene.gravity!r}")


def cracks(scene):
    """[(part, other part, pairs)] of Scene.cracks."""
    pairs = scene.mesh_report.coincident
    if len(pairs) == 0 or not scene.parts:
        return []
    names = list(scene.parts)
    owner = np.full(len(scene.points), -1, np.int64)   # one part per vertex (the last listed)
    for k, p in enumerate(scene.parts.values()):
        owner[scene.tets[p.tets].ravel()] = k
    a, b = owner[pairs[:, 0]], owner[pairs[:, 1]]
    out = {}
    for x, y in zip(a, b):
        if x >= 0 and y >= 0:
            key = (min(x, y), max(x, y))
            out[key] = out.get(key, 0) + 1
    return [(names[x], names[y], n) for (x, y), n in sorted(out.items())]


def loose_contacts(scene):
    """[(soft part, bone, triangles, area)] of Scene.loose_contacts."""
    soft = {p.name: p.tets for p in scene.parts.values() if p.kind in ("muscle", "tendon")}
    bones = scene.bone_tets()
    if not soft or not bones:
        return []
    return _loose_contacts(scene.points, scene.tets, soft, bones, shared_ok=scene.mesh_report.coincident)


def pin_targets(points, vertex_ids, positions=None) -> tuple:
    """(ids, (k, 3) targets) of Scene.pin, checked: ids in range, targets the
    rest positions or finite ``positions`` of shape (k, 3)."""
    ids = integer_ids(vertex_ids, "pin: vertex ids").ravel()
    if ids.size == 0:
        raise ValueError("pin: no vertex ids given")
    if ids.min() < 0 or ids.max() >= len(points):
        raise ValueError(f"pin: vertex ids must lie in [0, {len(points)}), got [{ids.min()}, {ids.max()}]")
    pos = points[ids] if positions is None else np.asarray(positions, dtype=np.float64)
    if pos.shape != (len(ids), 3):
        raise ValueError(f"pin: positions must have shape ({len(ids)}, 3), got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("pin: positions contain NaN or inf")
    return ids, pos
