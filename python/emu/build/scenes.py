"""Built-in scenes, made procedurally (no files): the fusiform muscle of
``emu compare``, the tests and the benchmarks, the arm of ``emu demo``, a
head on a ball joint and a chain of two movable bones."""
from __future__ import annotations

import numpy as np

from .procedural import NECK_MUSCLES, block_mesh
from .procedural import arm as arm_mesh
from .procedural import fusiform as fusiform_mesh
from .procedural import neck as neck_mesh
from ..model.scene import Scene

__all__ = ["fusiform", "arm", "neck", "chain", "beam_on_bone", "side_by_side", "elbow_wrap"]


def fusiform(resolution: int | None = None, *, tets: int | None = None, pins=("proximal",), length: float = 10.0,
             radius: float = 1.5, end_radius: float = 0.5, tendon_fraction: float = 0.12, warn: bool = True,
             **muscle) -> Scene:
    """The procedural spindle muscle (see emu.procedural.fusiform) as a Scene: the
    muscle part "belly" with the mesh's meridian fibres and, unless
    tendon_fraction is 0, the tendon caps as one tendon part "tendons".

    resolution  cross-section cells per side (None: 6, or chosen from ``tets``)
    tets        if given, choose the resolution giving about this many tets
    pins        names of the vertex sets to pin at rest: "proximal" (the z = 0
                end face), "distal" (z = length); () pins nothing. Both sets stay
                in ``scene.vertex_sets`` (scene files pin them by name)
    muscle      options of the belly (Scene.add_muscle: youngs, poisson, density,
                max_activation, acap_weight)
    """
    m = fusiform_mesh(6 if resolution is None else resolution, tets=tets, length=length, radius=radius,
                      end_radius=end_radius, tendon_fraction=tendon_fraction)
    s = Scene(m.points, m.tets, warn=warn)
    s.vertex_sets = {"proximal": m.proximal, "distal": m.distal}
    pins = [pins] if isinstance(pins, str) else list(pins)
    unknown = [p for p in pins if p not in s.vertex_sets]
    if unknown:
        raise ValueError(f"fusiform: unknown pin set(s) {', '.join(map(repr, unknown))} "
                         f"(known: {', '.join(s.vertex_sets)})")
    if m.is_tendon.any():
        s.add_muscle("belly", ~m.is_tendon, m.fibers[~m.is_tendon], **muscle)
        s.add_tendon("tendons", m.is_tendon)
    else:
        s.add_muscle("belly", np.arange(len(m.tets)), m.fibers, **muscle)
    if pins:
        s.pin(np.concatenate([s.vertex_sets[p] for p in pins]))
    return s


def arm(resolution: int = 2, *, forearm_fixed: bool = False, muscle_youngs: float = 6e4,
        max_activation: float = 1e5) -> Scene:
    """Two bones on a hinged elbow (see emu.procedural.arm): the humerus fixed, the
    forearm moved by a flexor and an extensor (Laplace fibres between each
    muscle's two attachments). The elbow axis is +z through the origin:
    flexion is a positive turn about it."""
    m = arm_mesh(resolution)
    s = Scene(m.points, m.tets)
    s.add_bone("humerus", m.parts["humerus"])
    s.add_bone("forearm", m.parts["forearm"], fixed=forearm_fixed)
    s.add_muscle("flexor", m.parts["flexor"], youngs=muscle_youngs, max_activation=max_activation)
    s.add_muscle("extensor", m.parts["extensor"], youngs=muscle_youngs, max_activation=max_activation)
    s.resolve_fibers()
    return s


def neck(resolution: int = 1, *, muscle_youngs: float = 6e4, max_activation: float = 1e5) -> Scene:
    """A head on a ball joint (see emu.procedural.neck): the torso fixed, the head
    moved by four neck muscles at its corners (Laplace fibres, torso to head).
    Firing them in turn rolls the head around."""
    m = neck_mesh(resolution)
    s = Scene(m.points, m.tets)
    s.add_bone("torso", m.parts["torso"])
    s.add_bone("head", m.parts["head"], fixed=False)
    for name in NECK_MUSCLES:
        s.add_muscle(name, m.parts[name], youngs=muscle_youngs, max_activation=max_activation)
    s.resolve_fibers()
    return s


def chain(resolution: int = 1, *, block: float = 1.0) -> Scene:
    """A chain of bones in the x-y plane, one block (``block``) thick: fixed bone
    "a", movable bone "b" hinged to it (they share one block edge along z), movable
    "c" hinged to "b" (a joint between two movable bones), muscle "m1" from a to b,
    "m2" from b to c and "m3" from c back to a, each with fibres along (1, 1, 0).

    8 blocks of 6 resolution^3 tets (resolution 1: 48 tets)."""
    points, tets, labels = block_mesh(
        {"a": [(0, 0)], "b": [(1, 1)], "c": [(2, 2)], "m1": [(0, 1)], "m2": [(1, 2)], "m3": [(2, 1), (1, 0)]},
        resolution, size=block)
    s = Scene(points, tets)
    s.add_bone("a", labels == 0)
    s.add_bone("b", labels == 1, fixed=False)
    s.add_bone("c", labels == 2, fixed=False)
    for i, name in enumerate(("m1", "m2", "m3")):
        s.add_muscle(name, labels == 3 + i, [1.0, 1.0, 0.0])
    return s


def _separate_blocks(blocks: list, resolution: int, block: float) -> tuple:
    """One mesh of several block meshes that share no vertex: blocks is a list of
    (name, block coordinates, offset (3,) in block units); returns points, tets
    and {name: tet ids}."""
    pts, tets, parts, n, m = [], [], {}, 0, 0
    for name, cells, offset in blocks:
        p, t, _ = block_mesh({name: cells}, resolution, block)
        pts.append(p + np.asarray(offset, float) * block)
        tets.append(t + n)
        parts[name] = np.arange(m, m + len(t))
        n, m = n + len(p), m + len(t)
    return np.vstack(pts), np.vstack(tets), parts


def beam_on_bone(resolution: int = 2, *, length: int = 4, gap: float = 0.2, block: float = 0.01,
                 muscle_youngs: float = 6e4) -> Scene:
    """A muscle beam ("muscle", fibres along x) ``gap`` blocks above a fixed bone
    slab ("bone") of the same length, sharing no vertex with it, pinned at its
    x = 0 end: under gravity (-z, 100 m/s^2 at the defaults) it sags through the
    bone unless contact is on (Scene.enable_contact). Blocks of ``block`` metres,
    6 resolution^3 tets each."""
    points, tets, parts = _separate_blocks(
        [("bone", [(i, 0) for i in range(length)], (0, 0, 0)),
         ("muscle", [(i, 0) for i in range(length)], (0, 0, 1 + gap))], resolution, block)
    s = Scene(points, tets)
    s.add_bone("bone", parts["bone"])
    s.add_muscle("muscle", parts["muscle"], [1.0, 0.0, 0.0], youngs=muscle_youngs)
    muscle_vertices = np.unique(tets[parts["muscle"]])
    s.pin(muscle_vertices[np.isclose(points[muscle_vertices, 0], 0.0)])
    return s


def side_by_side(resolution: int = 2, *, length: int = 4, gap: float = 0.1, block: float = 0.01,
                 muscle_youngs: float = 6e4, max_activation: float = 1e5) -> Scene:
    """Two muscle bars "left" and "right" (fibres along x, ``length`` blocks long,
    one block square) ``gap`` blocks apart in y, each pinned at its x = 0 end:
    fired, they shorten and thicken into each other unless contact is on."""
    points, tets, parts = _separate_blocks(
        [("left", [(i, 0) for i in range(length)], (0, 0, 0)),
         ("right", [(i, 0) for i in range(length)], (0, 1 + gap, 0))], resolution, block)
    s = Scene(points, tets)
    for name in ("left", "right"):
        s.add_muscle(name, parts[name], [1.0, 0.0, 0.0], youngs=muscle_youngs, max_activation=max_activation)
    x = points[:, 0]
    s.pin(np.flatnonzero(np.isclose(x, 0.0)))
    return s


def elbow_wrap(resolution: int = 2, *, length: int = 6, block: float = 0.02, muscle_youngs: float = 6e4,
               max_activation: float = 3e5) -> Scene:
    """The arm's two bones on their hinged elbow (emu.procedural.arm's layout: the
    humerus up +y, fixed; the forearm along +x, on the hinge about z through
    the origin), a flexor in the angle between them, and an extensor that runs
    behind the elbow one block clear of both bones, attached only at its two
    ends (to the humerus's back near its top, to the forearm's underside). As
    the flexor bends the elbow far, the extensor is stretched across the
    elbow's corner: with contact on it slides over the bone ends, without it
    cuts through them. 6 resolution^3 tets per block."""
    n = int(length)
    if n < 4:
        raise ValueError(f"length must be >= 4 blocks, got {length}")
    reach = n // 2 + 1
    blocks = {
        "humerus": [(-1, j) for j in range(n)],
        "forearm": [(i, -1) for i in range(n)],
        "flexor": [(i, j) for i in range(n) for j in range(n) if 3 <= i + j <= 5],
        # one block clear of the bones: a column at x in [-3, -2], a row at y in [-3, -2],
        # joined at the corner; tabs across the gap at the ends are its attachments
        "extensor": ([(-3, j) for j in range(-3, n)] + [(i, -3) for i in range(-2, reach)]
                     + [(-2, n - 1), (reach - 1, -2)]),
    }
    points, tets, labels = block_mesh(blocks, resolution, size=block)
    s = Scene(points, tets)
    s.add_bone("humerus", labels == 0)
    s.add_bone("forearm", labels == 1, fixed=False)
    for i, name in ((2, "flexor"), (3, "extensor")):
        s.add_muscle(name, labels == i, youngs=muscle_youngs, max_activation=max_activation)
    s.resolve_fibers()
    return s
