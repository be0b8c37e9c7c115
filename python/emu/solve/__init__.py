"""Solving a scene: the Solver and its parts, each its own module (import the
names from the module that defines them; the package imports nothing itself,
so that reading a scene file, which needs the options table and Frame, does
not load the solver).

    solver     the Solver (wiring only) and solve()
    options    the one table of solver options, their checks and their lowering to the core's
    load       a solve's load (activations, gravity, pins, scripted bones) and start as the core's
    solution   the Solution of a solve
    estimate   EMU's error estimate: FEM Newton steps at its answer and their certificate
    accuracy   accuracy mode's controller, against a small port (AccuracyPort)
    frames     the one warm-started frame loop (solve_frames), quasi-static or time steps
    dynamics   implicit time steps: the integrators' inertia and velocities (Dynamics, MotionState)
    advice     which method is faster for a scene, by the measured crossover
"""
