"""Built-in scenes, made procedurally (no files): the fusiform muscle of
``emu compare``, the tests and the benchmarks, the arm of ``emu demo`` and a
head on a ball joint."""
from __future__ import annotations

import numpy as np

from .meshes import NECK_MUSCLES
from .meshes import arm as arm_mesh
from .meshes import fusiform as fusiform_mesh
from .meshes import neck as neck_mesh
from .scene import Scene

__all__ = ["fusiform", "arm", "neck"]


def fusiform(resolution: int | None = None, *, tets: int | None = None, pins=("proximal",), length: float = 10.0,
             radius: float = 1.5, end_radius: float = 0.5, tendon_fraction: float = 0.12, warn: bool = True,
             **muscle) -> Scene:
    """The procedural spindle muscle (see emu.meshes.fusiform) as a Scene: the
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
    """Two bones on a hinged elbow (see emu.meshes.arm): the humerus fixed, the
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
    """A head on a ball joint (see emu.meshes.neck): the torso fixed, the head
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
