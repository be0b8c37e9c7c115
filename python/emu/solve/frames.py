"""A sequence of solves, each warm-started from the one before: the one frame
loop that ``emu run``, the demo, sweeps and the benchmark scripts run."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator

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


def solve_frames(solver, frames: Iterable, initial=None) -> Iterator:
    """The Solution of each of ``frames`` in order (Frame objects, or activation
    dicts), each solve warm-started from the solution before it, the first from
    ``initial`` (None: rest; a Solution of the same solver). A generator: a
    caller that stops early, or is interrupted, keeps the frames solved so far;
    EMU's accuracy mode carries its alpha from frame to frame in the solver."""
    prev = initial
    for frame in frames:
        f = frame if isinstance(frame, Frame) else Frame(activation=frame)
        prev = solver.solve(f.activation, normalized=f.normalized, gravity=f.gravity,
                            pin_positions=f.pin_positions, bone_poses=f.bone_poses or None, initial=prev)
        yield prev
