"""Solve times of both methods on the registry scenes, best of a few repeats
(the before/after instrument for changes to the per-iteration cost): FEM to
its default tolerance, EMU at a fixed alpha capped at a fixed number of
Newton steps (so both sides of a change do the same work). The phase
columns (Solution.phase_times, of the best repeat) say where the time went.

    python bench/studies/solve_times.py [--scenes realistic_biceps fusiform_20k arm_r5] [--threads 1]
        [--repeats 3] [--emu-iterations 10]
"""
from __future__ import annotations

import argparse

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["realistic_biceps", "fusiform_20k", "arm_r5"])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--emu-iterations", type=int, default=10)
    ap.add_argument("--alpha", type=float, default=100.0)
    a = ap.parse_args(argv)
    start_run(a.threads)
    phases = ("hessian", "preconditioner", "linear_solve", "line_search", "step", "other")  # Solution.phase_times
    print("| scene | method | iterations / CG | best solve s | " + " | ".join(phases) + " |")
    print("|---|---|---|---|" + "---|" * len(phases))
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        for method, kw in (("fem", {}), ("emu", dict(alpha=a.alpha, error_estimate=False,
                                                      max_iterations=a.emu_iterations))):
            solver = emu.Solver(scene, method, **kw)
            best = None
            for _ in range(a.repeats):
                sol = solver.solve(act, normalized=normalized)
                if best is None or sol.time_s < best.time_s:
                    best = sol
            cells = " | ".join(f"{best.phase_times[p]:.3f}" for p in phases)
            print(f"| {name} | {method} | {best.iterations} / {best.cg_iterations} | {best.time_s:.3f} | {cells} |",
                  flush=True)


if __name__ == "__main__":
    main()
