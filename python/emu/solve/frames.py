"""A sequence of solves, each warm-started from the one before: the one frame
loop that ``emu run``, the demo, sweeps and the benchmark scripts run."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from ..core.geometry import deformation_gradients

__all__ = ["Frame", "solve_frames"]


@dataclass(frozen=True)
class Frame:
    """One frame's load: Solver.solve's arguments of the same names.

    activation     {muscle: a} (absolute, or fractions with normalized=True)
    bone_poses     {bone: (R, t) or 4x4} placing scripted bones (None: at rest)
    gravity        a 3-vector (None: the scene's)
    pin_positions  (#pinned, 3) targets of the scene's pinned vertices (None: at rest)
    """
    activation: dict | None = None
    normalized: bool = False
    bone_poses: dict | None = None
    gravity: object = None
    pin_positions: object = None


def solve_frames(solver, frames: Iterable, initial=None, dynamics=None, state=None) -> Iterator:
    """The Solution of each of ``frames`` in order (Frame objects, or activation
    dicts), each solve warm-started from the one before, the first from
    ``initial`` (None: rest; a Solution of the same solver). A generator: a
    caller that stops early, or is interrupted, keeps the frames solved so far;
    EMU's accuracy mode carries its alpha from frame to frame in the solver.

    dynamics  an emu.Dynamics: each frame is a time step of dynamics.dt seconds
              with inertia, from ``state`` (an emu.MotionState;
              None: at rest, or at ``initial``'s positions, with zero velocities);
              each Solution carries the ``velocities`` at its end. None:
              quasi-static equilibria."""
    prev = initial
    if dynamics is None and state is not None:
        raise ValueError("solve_frames: a MotionState (state=) needs dynamics=emu.Dynamics(dt)")
    if dynamics is not None and state is None:
        from .dynamics import MotionState
        if initial is not None and not hasattr(initial, "positions"):
            raise TypeError("solve_frames with dynamics: initial must be a Solution of this solver (or give "
                            "state=emu.MotionState.at_rest(positions, velocities))")
        state = MotionState.at_rest(solver.scene.points if initial is None else initial.positions)
    for frame in frames:
        f = frame if isinstance(frame, Frame) else Frame(activation=frame)
        inertia = None if dynamics is None else dynamics.inertia(state)
        start = prev if dynamics is None or prev is not None else _start_of(solver, state.positions)
        prev = solver.solve(f.activation, normalized=f.normalized, gravity=f.gravity,
                            pin_positions=f.pin_positions, bone_poses=f.bone_poses or None, initial=start,
                            inertia=inertia)
        if dynamics is not None:
            state = dynamics.advance(state, prev.positions)
            prev.velocities = state.velocities.copy()
        yield prev


def _start_of(solver, positions):
    """A time stepping's first start from positions (n, 3): FEM takes them, EMU
    their per-tet deformation gradients (None at the rest shape: EMU's own start)."""
    if solver.method == "fem":
        return positions
    scene = solver.scene
    if np.array_equal(positions, scene.points):
        return None
    return deformation_gradients(scene.points, scene.tets, positions)
