"""Implicit time stepping: inertia as an incremental potential.

A time step of length h minimises E(x) - W(x) + (w / 2) |x - y|^2_M over the
positions x (the solver's energy, gravity's work, and the step's inertia on
the lumped vertex masses M from the parts' densities; energy/inertia.h), with
the predicted positions y and weight w of the integrator:

- backward Euler: y = x_n + h v_n, w = 1 / h^2; v_{n+1} = (x - x_n) / h
  (first order, numerically damped);
- BDF2: y = (4 x_n - x_{n-1}) / 3 + 2h (4 v_n - v_{n-1}) / 9, w = 1 / (2h/3)^2;
  v_{n+1} = (3 x - 4 x_n + x_{n-1}) / (2h) (second order; its first step is
  backward Euler's).

Mass-proportional (Rayleigh) damping, a force -c M v_{n+1}, is the quadratic
(c k / 2) |x - z|^2_M with z the step's v = 0 point and k = dv/dx (backward
Euler: z = x_n, k = 1/h; BDF2: z = (4 x_n - x_{n-1}) / 3, k = 3 / (2h)),
folded into w and y. Pinned vertices and fixed or scripted bones are moved by
the load; their velocities follow from their positions by the same formulas.
Movable bones are rigid bodies whose mass and inertia are their vertices'
lumped masses. docs/DESIGN.md, "Dynamics".
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ..core.checks import signed_volumes

__all__ = ["Dynamics", "MotionState", "INTEGRATORS", "vertex_masses"]

INTEGRATORS = ("backward_euler", "bdf2")


@dataclass(frozen=True)
class Dynamics:
    """How frames become time steps.

    dt            seconds per step (one frame of a sequence), > 0
    integrator    "bdf2" (second order, the default) or "backward_euler" (first
                  order: the robust choice, which damps every vibration numerically)
    mass_damping  Rayleigh's mass-proportional coefficient c (1/s): a force -c m v on every vertex
    """
    dt: float
    integrator: str = "bdf2"
    mass_damping: float = 0.0

    def __post_init__(self):
        if not (_real(self.dt) and self.dt > 0):
            raise ValueError(f"dynamics dt must be a positive number of seconds, got {self.dt!r}")
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"dynamics integrator must be one of {', '.join(INTEGRATORS)}, got "
                             f"{self.integrator!r}")
        if not (_real(self.mass_damping) and self.mass_damping >= 0):
            raise ValueError(f"dynamics mass_damping must be >= 0 (1/s), got {self.mass_damping!r}")

    def inertia(self, state: "MotionState") -> tuple:
        """(w, y): the next step's inertia weight and predicted positions (#V, 3) from state."""
        h, x, v = float(self.dt), state.positions, state.velocities
        if self._bdf2(state):
            xp, vp = state.previous_positions, state.previous_velocities
            y = (4.0 * x - xp) / 3.0 + (2.0 * h / 9.0) * (4.0 * v - vp)
            w, z, k = 1.0 / (2.0 * h / 3.0) ** 2, (4.0 * x - xp) / 3.0, 1.5 / h
        else:
            y, w, z, k = x + h * v, 1.0 / h ** 2, x, 1.0 / h
        c = self.mass_damping * k
        if c > 0:
            y = (w * y + c * z) / (w + c)
            w = w + c
        return w, y

    def advance(self, state: "MotionState", positions) -> "MotionState":
        """The state after a step that ended at positions (#V, 3)."""
        x = np.array(positions, dtype=np.float64)
        h = float(self.dt)
        if self._bdf2(state):
            v = (3.0 * x - 4.0 * state.positions + state.previous_positions) / (2.0 * h)
        else:
            v = (x - state.positions) / h
        return MotionState(x, v, state.positions, state.velocities, state.steps + 1)

    def _bdf2(self, state: "MotionState") -> bool:
        """Whether this step is BDF2's (its first step is backward Euler's: no step before)."""
        return self.integrator == "bdf2" and state.previous_positions is not None


def vertex_masses(scene) -> np.ndarray:
    """Lumped vertex masses (#V): each tet's mass (its part's density x volume)
    split equally among its four corners, as the solvers' inertia and gravity
    take them on every vertex that moves. Every tet counts here; the solvers
    leave out fixed bones' tets, so a vertex on a fixed bone (which never
    moves) weighs less there."""
    volume = np.abs(signed_volumes(scene.points, scene.tets))
    density = np.zeros(len(scene.tets))
    for part in scene.parts.values():
        density[part.tets] = part.density
    m = np.zeros(len(scene.points))
    np.add.at(m, scene.tets.ravel(), np.repeat(0.25 * density * volume, 4))
    return m


def _real(value) -> bool:
    """A finite real number (not a bool)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


@dataclass
class MotionState:
    """Positions and velocities (#V, 3) after a step, and the step before's
    (BDF2 reads both; None before the first step)."""
    positions: np.ndarray
    velocities: np.ndarray
    previous_positions: np.ndarray | None = None
    previous_velocities: np.ndarray | None = None
    steps: int = 0

    def __post_init__(self):
        shape = np.shape(self.positions)
        if len(shape) != 2 or shape[1] != 3:
            raise ValueError(f"MotionState positions must be a (#V, 3) array, got shape {shape}")
        if np.shape(self.velocities) != shape:
            raise ValueError(f"MotionState velocities must have the positions' shape {shape}, got "
                             f"{np.shape(self.velocities)}")
        if (self.previous_positions is None) != (self.previous_velocities is None):
            raise ValueError("MotionState needs both previous_positions and previous_velocities (the step "
                             "before, for BDF2) or neither")
        for name in ("previous_positions", "previous_velocities"):
            if getattr(self, name) is not None and np.shape(getattr(self, name)) != shape:
                raise ValueError(f"MotionState {name} must have the positions' shape {shape}")

    @classmethod
    def at_rest(cls, positions, velocities=None) -> "MotionState":
        """A start at positions (#V, 3) with velocities (#V, 3; None: zero)."""
        x = np.array(positions, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3 or not np.all(np.isfinite(x)):
            raise ValueError(f"positions must be a finite (#V, 3) array, got shape {x.shape}")
        v = np.zeros_like(x) if velocities is None else np.array(velocities, dtype=np.float64)
        if v.shape != x.shape or not np.all(np.isfinite(v)):
            raise ValueError(f"velocities must be a finite array of the positions' shape {x.shape}, got {v.shape}")
        return cls(x, v)
