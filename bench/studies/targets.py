"""Issue 9's time-to-error targets, one run: per target scene, FEM Newton's
and EMU's time to 1% vertex error to the converged FEM answer (setup +
solve), the ratio against the target, and where EMU's time goes up to the
Newton step after which it stays within 1%: its setup, the per-step work
outside CG (Hessian blocks; preconditioner and bone coarse-space rebuilds;
line search; the rest) and CG (iterations x cost of one). The last columns
say what the target leaves: EMU's time budget (FEM's time over the target
ratio), and how many CG iterations fit in it at today's cost per iteration
once the setup and the per-step work are paid (negative: they alone exceed it).

    python bench/studies/targets.py [--scenes realistic_biceps arm_r5 fusiform_80k] [--alphas 100 300 1000]
                            [--threads 1]

EMU runs at each alpha given (error estimate off, as in error_vs_time.py);
the fastest to 1% is reported. The phase split comes from a second solve
stopped after that Newton step (max_iterations), whose time is printed too.
"""
from __future__ import annotations

import argparse
import time

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run
from error_vs_time import curve
from emu.core.geometry import time_within

TARGET_ERROR = 0.01
# the ratios FEM Newton / EMU at 1%, 1 thread: 3x on the bone scenes
# (RATIOS.get's default), 10x on the fusiform at 80k tets
RATIOS = {"fusiform_80k": 10.0}
FIXED = ("hessian", "preconditioner", "line_search", "step", "other")  # Solution.phase_times outside CG


def recorded(scene, method, act, normalized, reference, **options):
    """(time to 1% (setup + solve), the Newton step after which it stays within)."""
    t, e, _ = curve(scene, method, act, normalized, reference, **options)
    reached = time_within(t, e, TARGET_ERROR)
    return reached, (int(sum(1 for ti in t if ti < reached)) if reached < float("inf") else None)


def phases_to(scene, act, normalized, steps, **options):
    """Setup, phase times and CG count of an EMU solve stopped after `steps` Newton steps."""
    t0 = time.perf_counter()
    solver = emu.Solver(scene, "emu", max_iterations=steps, **options)
    setup = time.perf_counter() - t0
    sol = solver.solve(act, normalized=normalized)
    return setup, sol


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["realistic_biceps", "arm_r5", "fusiform_80k"])
    ap.add_argument("--alphas", type=float, nargs="*", default=[100, 300, 1000])
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    print("| scene | tets | FEM to 1% s | EMU to 1% s (alpha, Newton / CG) | FEM / EMU | target | "
          "EMU's budget s | EMU setup s | per-step work s | CG s (ms each) | solve stopped there s | "
          "CG iterations the budget leaves |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        reference = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
        fem_t, _ = recorded(scene, "fem", act, normalized, reference)
        best = None
        for alpha in a.alphas:
            t, steps = recorded(scene, "emu", act, normalized, reference, alpha=alpha, error_estimate=False)
            if steps is not None and (best is None or t < best[0]):
                best = (t, steps, alpha)
        ratio = RATIOS.get(name, 3.0)
        if best is None:
            print(f"| {name} | {len(scene.tets)} | {fem_t:.3f} | not reached at alphas {a.alphas} | - | "
                  f"{ratio:g}x | {fem_t / ratio:.3f} | - | - | - | - | - |")
            continue
        emu_t, steps, alpha = best
        setup, sol = phases_to(scene, act, normalized, steps, alpha=alpha, error_estimate=False)
        ph = sol.phase_times
        fixed = sum(ph[p] for p in FIXED)
        cg_s = ph["linear_solve"]
        per_cg = cg_s / sol.cg_iterations if sol.cg_iterations else float("nan")   # none: 1% at the start
        budget = fem_t / ratio
        left = (budget - setup - fixed) / per_cg if sol.cg_iterations else float("nan")
        print(f"| {name} | {len(scene.tets)} | {fem_t:.3f} | {emu_t:.3f} ({alpha:g} mu, {sol.iterations} / "
              f"{sol.cg_iterations}) | {fem_t / emu_t:.1f}x | {ratio:g}x | {budget:.3f} | {setup:.3f} | "
              f"{fixed:.3f} | {cg_s:.3f} ({1e3 * per_cg:.1f}) | {setup + sol.time_s:.3f} | {left:.0f} |", flush=True)


if __name__ == "__main__":
    main()
