"""A muscle's tendons: the tendons through which it attaches to bones, and
splitting a muscle's tets near its bone attachments into a tendon part
(Scene.tendon_attachments, Scene.split_tendons)."""
from __future__ import annotations

import numpy as np

from ..core.fibers import attachment_fibers, attachments
from ..core.geometry import tet_vertices


def tendon_attachments(scene, muscle: str) -> dict:
    """{bone name: (tendon name, vertex ids)} where a tendon sharing vertices
    with the muscle shares vertices with a bone."""
    p = scene._part(muscle, "muscle")
    mine = tet_vertices(scene.tets[p.tets], len(scene.points))
    out = {}
    for t in scene.parts.values():
        if t.kind != "tendon" or not np.intersect1d(tet_vertices(scene.tets[t.tets], len(scene.points)), mine).size:
            continue
        for bone, ids in attachments(scene.tets, t.tets, scene.bone_tets()).items():
            out.setdefault(bone, (t.name, ids))
    return out


def tets_near_attachments(scene, muscle: str, distance: float) -> np.ndarray:
    """(k,) bool per tet of the muscle: its centroid within ``distance`` of one
    of the muscle's bone attachments (ValueError where there is none, or where
    all or none of its tets are that near). A muscle without fibres and two
    attachments gets its attachment fibres first: the split hides the
    attachments behind the tendons."""
    p = scene._part(muscle, "muscle")
    if not distance > 0:
        raise ValueError(f"split_tendons: distance must be positive, got {distance}")
    att = scene.attachments(muscle)
    if not att:
        raise ValueError(f"muscle '{muscle}' shares no vertex with a bone: there is no attachment to "
                         "measure from; label the tendon tets yourself (add_tendon)")
    if p.fibers is None and len(att) == 2:
        p.fibers = attachment_fibers(scene.points, scene.tets, p.name, p.tets, att)
    anchor = scene.points[np.unique(np.concatenate(list(att.values())))]
    c = scene.points[scene.tets[p.tets]].mean(axis=1)
    near = np.zeros(len(c), bool)
    for i in range(0, len(c), 4096):  # chunked: (chunk x attachments) distances
        d2 = ((c[i:i + 4096, None, :] - anchor[None, :, :]) ** 2).sum(axis=2)
        near[i:i + 4096] = d2.min(axis=1) <= distance * distance
    if near.all():
        raise ValueError(f"split_tendons: every tet of '{muscle}' lies within {distance} of an attachment; "
                         "use a smaller distance")
    if not near.any():
        raise ValueError(f"split_tendons: no tet of '{muscle}' lies within {distance} of an attachment")
    return near
