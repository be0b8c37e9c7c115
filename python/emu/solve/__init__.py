"""Solving a scene: the Solver and its parts.

    solver     the Solver (wiring only) and solve()
    options    the one table of solver options, their checks and their lowering to the core's
    load       a solve's load (activations, gravity, pins, scripted bones) as the core's
    solution   the Solution of a solve
    estimate   EMU's error estimate: FEM Newton steps at its answer and their certificate
    accuracy   accuracy mode's controller, against a small port (AccuracyPort)
    frames     the one warm-started frame loop (solve_frames)
    advice     which method is faster for a scene, by the measured crossover

The names below load their module on first use, so that reading a scene file
(which needs the options table and Frame) does not load the solver.
"""
import importlib

_HOME = {"Solver": "solver", "solve": "solver", "STEPS": "solver", "NeutralModeWarning": "solver",
         "METHODS": "options", "Solution": "solution", "AccuracyWarning": "accuracy",
         "ActivationWarning": "load", "Frame": "frames", "solve_frames": "frames"}

__all__ = list(_HOME)


def __getattr__(name: str):
    if name in _HOME:
        return getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
