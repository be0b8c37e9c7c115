"""Clamped against reflected eigenvalues in the PSD-filtered element Hessian
(Solver(eigen_filter="clamp" | "abs")), and FEM's negative-curvature step on
and off, on the hard cases: the near-incompressible stress case (Poisson
0.4999, a saddle: docs/stability.md) and big_muscle with both bones fixed at
a = 1.33e4 (docs/DESIGN.md, "Open problem: hard isometric cases").

    python bench/studies/eigen_filter.py [--cases poisson_4999 big_muscle_isometric] [--threads 1]

EMU at alpha = 100 mu to the strict tolerance, no error estimate; FEM
Newton to its strict tolerance; every solve capped at 3000 iterations.
"""
from __future__ import annotations

import argparse
import time
import warnings

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run
from stability import pinned_muscle

CASES = {
    "poisson_4999": lambda: (pinned_muscle(poisson=0.4999), {"belly": 5e4}),
    "big_muscle_isometric": lambda: (SCENES["big_muscle_isometric"]()[0], {"muscle": 1.33e4}),
}
VARIANTS = [("fem", dict(eigen_filter="clamp")), ("fem", dict(eigen_filter="abs")),
            ("fem", dict(eigen_filter="clamp", negative_curvature=False)),
            ("fem", dict(eigen_filter="abs", negative_curvature=False)),
            ("emu", dict(eigen_filter="clamp")), ("emu", dict(eigen_filter="abs"))]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    print("| case | method | options | result | Newton (/ CG) | filtered steps | negative-curvature steps | energy | s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in a.cases:
        scene, act = CASES[name]()
        for method, options in VARIANTS:
            kw = dict(alpha=100.0, error_estimate=False) if method == "emu" else {}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                sol = emu.Solver(scene, method, max_iterations=3000, **kw, **options).solve(act)
                seconds = time.perf_counter() - t0
            opts = ", ".join(f"{k}={v}" for k, v in options.items())
            cg = f" / {sol.cg_iterations}" if sol.cg_iterations else ""
            print(f"| {name} | {method} | {opts} | {sol.status.split(':')[0]} | {sol.iterations}{cg} | "
                  f"{sol.filtered_steps} | {sol.negative_curvature_steps} | {sol.energy:.7g} | {seconds:.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
