"""Validate EMU's error estimate (Solution.error_estimate) against the true
error to the converged FEM answer, over scenes and alpha.

For each scene: FEM to a tight tolerance (the reference), then EMU at each
alpha; prints a Markdown table of the true vertex error, the estimate, their
ratio (the target band is [0.5, 2]), the ratio one FEM Newton correction x1
alone would give (|x - x1| / true: the estimate before its second step), the
certificate (Solution.error_estimate_certified: the second step contracted),
EMU's solve time and the estimate's time.

    python bench/studies/error_estimate.py [--scenes fusiform simple_joint ...] [--alphas 10 30 100 300 1000]
    python bench/studies/error_estimate.py --variants ...   # estimate / true of each way to take the correction

--variants adds, per case, estimate / true for one Newton step with the exact
matrix (where definite, else filtered), with the filtered one, with the
lower-energy one of both, and for up to two lower-energy steps (the default).
"""
from __future__ import annotations

import argparse
import time
import warnings

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES



def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_20k", "simple_joint", "simple_joint_free", "big_muscle_free",
                                                    "big_muscle_isometric", "arm_r5", "neck_r2", "realistic_biceps"])
    ap.add_argument("--alphas", type=float, nargs="*", default=[10, 30, 100, 300, 1000])
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--steps", type=int, default=2, help="error_estimate_steps (Newton correction steps at most)")
    ap.add_argument("--variants", action="store_true", help="also the other ways to take the correction")
    a = ap.parse_args(argv)
    if a.threads:
        emu.runtime.set_threads(a.threads)
    warnings.simplefilter("ignore")
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}; "
          f"error_estimate_steps = {a.steps}")
    print()
    variants = [("exact", 1), ("filtered", 1), ("lower-energy", 1), ("lower-energy", 2)] if a.variants else []
    extra = "".join(f" {h} x{k} |" for h, k in variants)
    print("| scene | tets | alpha / mu | true error | estimate | estimate / true | x1 alone / true | certified | "
          "EMU solve s | estimate s |" + extra)
    print("|---|---|---|---|---|---|---|---|---|---|" + "---|" * len(variants))
    outside = 0
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        fem_solver = emu.Solver(scene, "fem", rtol_grad=1e-9)
        fem = fem_solver.solve(act, normalized=normalized)
        load = fem_solver.load_case(act, normalized=normalized)
        for alpha in a.alphas:
            sol = emu.Solver(scene, "emu", alpha=alpha, error_estimate_steps=a.steps).solve(act, normalized=normalized)
            true = emu.vertex_error(sol, fem)
            est = sol.error_estimate
            ratio = est / true if est is not None and true > 0 else float("nan")
            one = (emu.vertex_error(sol.positions, sol.fem_correction) / true
                   if sol.fem_correction is not None and true > 0 else float("nan"))
            outside += not (0.5 <= ratio <= 2)
            cols = ""
            for h, k in variants:
                x1 = fem_solver._core.newton_correction(load, sol.positions, h, k)
                cols += f" {emu.vertex_error(sol.positions, x1) / true:.2f} |"
            print(f"| {name} | {len(scene.tets)} | {alpha:g} | {true:.2e} | "
                  f"{'-' if est is None else f'{est:.2e}'} | {ratio:.2f} | {one:.2f} | "
                  f"{'-' if sol.error_estimate_certified is None else ('yes' if sol.error_estimate_certified else 'no')} | "
                  f"{sol.solve_time_s:.2f} | "
                  f"{sol.error_estimate_time_s:.2f} |" + cols, flush=True)
    print(f"\n{outside} case(s) outside [0.5, 2]")


if __name__ == "__main__":
    main()
