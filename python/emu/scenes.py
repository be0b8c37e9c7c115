"""Built-in scenes, made procedurally (no files): the arm of ``emu demo`` and a
head on a ball joint."""
from __future__ import annotations

from .meshes import NECK_MUSCLES
from .meshes import arm as arm_mesh
from .meshes import neck as neck_mesh
from .scene import Scene

__all__ = ["arm", "neck"]


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
