"""How much FEM's Newton corrections improve EMU's answer (the corrections
the error estimate already computes): EMU once at a fixed alpha with the
accuracy stopping rule, then x1 = newton_correction(x) and x2 =
newton_correction(x1) on the estimator's FEM system (the second on its lagged
factor), each one's vertex error to the converged FEM answer and seconds.
For the design question whether accuracy mode should return corrected
positions instead of re-solving at a larger alpha (docs/DESIGN.md).

    python bench/studies/fem_correction.py [--scenes arm_r5 fusiform_20k realistic_biceps simple_joint_free big_muscle_free]
        [--alpha 100] [--threads 1]
"""
from __future__ import annotations

import argparse
import time

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*",
                    default=["arm_r5", "fusiform_20k", "realistic_biceps", "simple_joint_free", "big_muscle_free"])
    ap.add_argument("--alpha", type=float, default=100.0)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    print("| scene | EMU s | EMU error | its estimate (s) | x1 error (s) | x2 error (s) |")
    print("|---|---|---|---|---|---|")
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        ref = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
        solver = emu.Solver(scene, "emu", alpha=a.alpha, accuracy=0.01)
        solver.accuracy = None   # the accuracy stopping rule, one solve at this alpha
        sol = solver.solve(act, normalized=normalized)
        load = solver.load_case(act, normalized)
        own = sol.emu_positions   # EMU's own answer (accuracy mode may have corrected or settled it)
        x, cells = own, []
        for _ in range(2):
            t0 = time.perf_counter()
            x = solver._estimator.fem.newton_correction(load, x, max_steps=solver.error_estimate_steps)
            cells.append(f"{emu.vertex_error(x, ref.positions):.2e} ({time.perf_counter() - t0:.2f})")
        print(f"| {name} | {sol.solve_time_s:.2f} | {emu.vertex_error(own, ref.positions):.2e} | "
              f"{sol.error_estimate:.2e} ({sol.error_estimate_time_s:.2f}) | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
