"""The integrators (emu.Dynamics, FEM) on a bar's first vibration and on a
forearm swinging under gravity.

1. The bar: the built-in fusiform muscle pinned at one end, released at rest
   from a small displacement along its first mode (linear regime), three
   periods: the period and the amplitude kept per period against the mesh's
   own generalised eigenproblem K v = w^2 M v (K: FEM's Newton matrix at rest,
   M: the lumped masses), for steps per period from coarse to fine; then from
   a large displacement (nonlinear), where the period is the large motion's
   and the energy's largest rise above its start is what a symplectic
   integrator risks.
   Implicit midpoint (measured here, not shipped: see midpoint_steps) beside
   emu.Dynamics' backward Euler and BDF2.
2. The swing: the built-in arm (emu.scenes.arm(1): forearm on a hinge, two
   passive muscles) released from its rest shape under gravity, one second:
   the energy (elastic, gravity's, kinetic with the lumped masses) lost as a
   fraction of what the swing has (start less the static equilibrium), the
   forearm's angle range in the last quarter second against the first, and
   whether the energy ever rose above its start.
    python bench/studies/dynamics_bar.py [--resolution 2] [--steps 10 24 50 100] [--periods 3]
        [--swing-dt 0.01 0.005] [--amplitudes 0.001 0.1] [--drop-dt 0.02 0.01 0.005 0.0025]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np
import scipy.linalg

import emu
from emu._core import testing
from emu.build.procedural import block_mesh

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import start_run  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=2)
    ap.add_argument("--steps", type=int, nargs="*", default=[10, 24, 50, 100])
    ap.add_argument("--periods", type=int, default=3)
    ap.add_argument("--swing-dt", type=float, nargs="*", default=[0.01, 0.005])
    ap.add_argument("--amplitudes", type=float, nargs="*", default=[1e-3, 0.1],
                    help="the bar's initial displacement / the mesh's extent (1e-3: linear; 0.1: nonlinear)")
    ap.add_argument("--drop-dt", type=float, nargs="*", default=[0.02, 0.01, 0.005, 0.0025])
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    for amplitude in a.amplitudes:
        bar(a, amplitude)
    swing(a)
    drop(a)


def dropped_bone_scene():
    """A fixed block, a passive muscle block and a bone block on no joint, side by side along x
    (2 x 2 x 2 each), gravity along -y."""
    pts, tets, lab = block_mesh({"base": [(0, 0, 0)], "m": [(1, 0, 0)], "loose": [(2, 0, 0)]}, 2)
    scene = emu.Scene(pts, tets, warn=False)
    scene.add_bone("base", lab == 0)
    scene.add_muscle("m", lab == 1, [1.0, 0.3, 0.1])
    scene.add_bone("loose", lab == 2, fixed=False)
    scene.gravity = [0.0, -9.81, 0.0]
    return scene


def drop(a):
    scene = dropped_bone_scene()
    m = emu.vertex_masses(scene)
    solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
    load = solver.load_case({})
    energy = lambda x, v: testing.energy(solver._core, load, x) + 0.5 * np.sum(m[:, None] * v ** 2)  # noqa: E731
    e0 = energy(scene.points, np.zeros_like(scene.points))
    motion = e0 - testing.energy(solver._core, load, solver.solve({}).positions)
    print(f"\na bone on no joint hanging by a passive muscle, released under gravity ({len(scene.tets)} tets), "
          f"1 s; motion energy {motion:.4g}\n")
    print("| integrator | dt s | energy lost / motion energy | lost / lost at twice the step | "
          "largest rise above start | Newton per step |")
    print("|---|---|---|---|---|---|")
    for integrator in ("backward_euler", "bdf2"):
        before = None
        for dt in a.drop_dt:
            n = int(round(1.0 / dt))
            energies, newton = [], 0
            for sol in emu.solve_frames(solver, [{}] * n, dynamics=emu.Dynamics(dt, integrator)):
                energies.append(energy(sol.positions, sol.velocities))
                newton += sol.iterations
            lost = (e0 - energies[-1]) / motion
            ratio = "-" if before is None else f"{lost / before:.2f}"
            print(f"| {integrator} | {dt:g} | {lost:.4f} | {ratio} | {max(0.0, max(energies) - e0) / motion:.1e} | "
                  f"{newton / n:.1f} |")
            before = lost


def midpoint_steps(solver, steps: int, dt: float, x0):
    """Implicit midpoint from x0 at rest: each step solves for the midpoint z as a
    backward Euler step of dt / 2 (inertia weight 4 / dt^2, predicted x_n + dt v_n / 2),
    then x_{n+1} = 2 z - x_n, v_{n+1} = 2 (x_{n+1} - x_n) / dt - v_n. Yields
    (positions, velocities, Newton steps). Soft tissue only: with a rotating bone,
    2 z - x_n is not a rigid placement of its vertices (why emu ships BDF2)."""
    x, v = np.array(x0, dtype=np.float64), np.zeros_like(x0)
    for _ in range(steps):
        sol = solver.solve({}, initial=x, inertia=(4.0 / dt ** 2, x + 0.5 * dt * v))
        if not sol.converged:
            raise RuntimeError(f"the midpoint's solve did not converge ({sol.status})")
        x_new = 2.0 * sol.positions - x
        v = 2.0 * (x_new - x) / dt - v
        x = x_new
        yield x, v, sol.iterations


def bar(a, amplitude: float):
    scene = emu.scenes.fusiform(a.resolution, warn=False)
    solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
    load = solver.load_case({})
    _, K = testing.reduced_system(solver._core, load, scene.points, True)
    free = np.setdiff1d(np.arange(len(scene.points)), scene.pinned)
    m = emu.vertex_masses(scene)
    M = np.repeat(m[free], 3)
    w2, V = scipy.linalg.eigh(np.asarray(K), np.diag(M), subset_by_index=[0, 0])
    period, mode = 2 * np.pi / np.sqrt(w2[0]), V[:, 0]
    energy = lambda x, v: testing.energy(solver._core, load, x) + 0.5 * np.sum(m[:, None] * v ** 2)  # noqa: E731
    print(f"fusiform r={a.resolution}: {len(scene.tets)} tets; first period {period:.4g} s (eigenproblem); "
          f"released from {amplitude:g} x its extent along the first mode\n")
    print("| integrator | steps per period | period / exact | amplitude kept per period | "
          "largest energy rise / start | Newton per step |")
    print("|---|---|---|---|---|---|")
    amp = amplitude * np.abs(scene.points).max() / np.abs(mode).max()
    x0 = scene.points.copy()
    x0[free] += amp * mode.reshape(-1, 3)
    e0 = energy(x0, np.zeros_like(x0)) - testing.energy(solver._core, load, scene.points)
    for integrator in ("backward_euler", "bdf2", "implicit_midpoint"):
        for n in a.steps:
            dt = period / n
            q, newton, rise = [(x0 - scene.points)[free].ravel() @ (M * mode)], 0, 0.0
            try:
                for x, v, iterations in steps_of(solver, integrator, n * a.periods, dt, x0):
                    q.append((x - scene.points)[free].ravel() @ (M * mode))
                    newton += iterations
                    rise = max(rise, energy(x, v) - energy(x0, np.zeros_like(x0)))
            except RuntimeError as e:
                print(f"| {integrator} | {n} | diverged at step {len(q)}: {e} | | {rise / e0:.1e} | |")
                continue
            q = np.array(q)
            z = [k + q[k] / (q[k] - q[k + 1]) for k in range(len(q) - 1) if q[k] * q[k + 1] < 0]
            measured = 2 * np.mean(np.diff(z)) * dt if len(z) >= 3 else float("nan")
            kept = (np.abs(q[-n:]).max() / abs(q[0])) ** (1.0 / (a.periods - 1)) if a.periods > 1 else float("nan")
            print(f"| {integrator} | {n} | {measured / period:.4f} | {kept:.3f} | {rise / e0:.1e} | "
                  f"{newton / len(q[1:]):.1f} |")
    print()


def steps_of(solver, integrator: str, steps: int, dt: float, x0):
    """(positions, velocities, Newton steps) of each step from x0 at rest."""
    if integrator == "implicit_midpoint":
        yield from midpoint_steps(solver, steps, dt, x0)
        return
    for sol in emu.solve_frames(solver, [{}] * steps, dynamics=emu.Dynamics(dt, integrator),
                                state=emu.MotionState.at_rest(x0)):
        yield sol.positions, sol.velocities, sol.iterations


def swing(a):
    scene = emu.scenes.arm(1)
    scene.gravity = np.array([0.0, -9.81, 0.0])
    m = emu.vertex_masses(scene)
    solver = emu.Solver(scene, "fem", rtol_grad=1e-10)
    load = solver.load_case({})
    energy = lambda x, v: testing.energy(solver._core, load, x) + 0.5 * np.sum(m[:, None] * v ** 2)  # noqa: E731
    e0 = energy(scene.points, np.zeros_like(scene.points))
    e_static = testing.energy(solver._core, load, solver.solve({}).positions)
    print(f"\nthe arm's forearm released under gravity (arm(1), {len(scene.tets)} tets), 1 s; swing energy "
          f"{e0 - e_static:.3g} J\n")
    print("| integrator | dt s | energy lost / swing energy | angle range last 0.25 s / first 0.25 s | "
          "energy above start | Newton per step |")
    print("|---|---|---|---|---|---|")
    for integrator in ("backward_euler", "bdf2"):
        for dt in a.swing_dt:
            n = int(round(1.0 / dt))
            angles, energies, newton = [], [], 0
            for sol in emu.solve_frames(solver, [{}] * n, dynamics=emu.Dynamics(dt, integrator)):
                angles.append(emu.bone_angle(scene, sol.positions, "forearm"))
                energies.append(energy(sol.positions, sol.velocities))
                newton += sol.iterations
            q = max(1, n // 4)
            first, last = np.ptp(angles[:q]), np.ptp(angles[-q:])
            print(f"| {integrator} | {dt:g} | {(e0 - energies[-1]) / (e0 - e_static):.2f} | {last / first:.2f} | "
                  f"{max(energies) - e0:.2g} | {newton / n:.1f} |")


if __name__ == "__main__":
    main()
