"""EMU solver variants side by side: the time to reach 1% (and 0.5%) of the
converged FEM answer, and to converge, per scene and alpha, for Solver
options given on the command line (one --variant per run, comma-separated
key=value pairs, values parsed as Python literals where they can be).

    python bench/studies/variants.py --scenes fusiform_20k --alphas 300 \\
        --variant preconditioner='"woodbury"' --variant preconditioner='"schur"' \\
        --variant preconditioner='"schur"',preconditioner_refresh=1000 [--threads 1]
"""
from __future__ import annotations

import argparse
import ast

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run


def parse_variant(text: str) -> dict:
    """'a=1,b="x"' -> {"a": 1, "b": "x"} (a value that is no Python literal stays a string)."""
    out = {}
    for item in filter(None, text.split(",")):
        key, _, value = item.partition("=")
        try:
            out[key.strip()] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[key.strip()] = value
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_20k"])
    ap.add_argument("--alphas", type=float, nargs="*", default=[300.0])
    ap.add_argument("--variant", action="append", default=[], help="Solver options, e.g. modes=48,preconditioner_refresh=1")
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    variants = [parse_variant(v) for v in a.variant] or [{}]
    start_run(a.threads)
    print("| scene | alpha (mu) | variant | setup s | to 1% s | to 0.5% s | converged s | Newton / CG | factorisations |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        ref = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
        for alpha in a.alphas:
            for kw in variants:
                label = ", ".join(f"{k}={v}" for k, v in kw.items()) or "defaults"
                solver = emu.Solver(scene, "emu", alpha=alpha, error_estimate=False, **kw)
                sol = solver.solve(act, normalized=normalized, record_iterates=True)
                t1, t05 = (emu.time_to_error(sol, ref, e) for e in (0.01, 0.005))
                state = "" if sol.converged else " (not converged)"
                print(f"| {name} | {alpha:g} | {label} | {solver.setup_time_s:.2f} | {t1:.2f} | {t05:.2f} | "
                      f"{sol.time_s:.2f}{state} | {sol.iterations} / {sol.cg_iterations} | {sol.factorizations} |",
                      flush=True)


if __name__ == "__main__":
    main()
