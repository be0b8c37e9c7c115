#!/usr/bin/env python3
"""EMU's error against run time as alpha varies, next to FEM's run time.

    python bench/studies/alpha_sweep.py [--tets 8000] [--alphas 10 30 100 300 1000 3000] [--json out.json]

alpha is relative to the muscle's shear modulus. Error: largest vertex
distance to the converged FEM answer over the bounding-box diagonal.
"""
from __future__ import annotations

import argparse
import json
import sys

import emu
from emu_vs_fem import build_scene


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tets", type=int, default=8000)
    ap.add_argument("--activation", type=float, default=5e4)
    ap.add_argument("--alphas", type=float, nargs="+", default=[10, 30, 100, 300, 1000, 3000])
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    if a.threads:
        emu._core.set_threads(a.threads)
    scene = build_scene(a.tets)
    act = {"belly": a.activation}
    fem = emu.Solver(scene, "fem").solve(act)
    rows = [{"method": "fem", "alpha": None, "error": 0.0, "time_s": fem.time_s + fem.setup_time_s,
             "iterations": fem.iterations, "cg_iterations": 0, "converged": fem.converged}]
    for alpha in a.alphas:
        s = emu.Solver(scene, "emu", alpha=alpha).solve(act)
        rows.append({"method": "emu_newton_krylov", "alpha": alpha, "error": emu.vertex_error(s, fem),
                     "time_s": s.time_s + s.setup_time_s, "iterations": s.iterations,
                     "cg_iterations": s.cg_iterations, "converged": s.converged})
    info = emu.info()
    print(f"fusiform muscle, {len(scene.tets)} tets, a = {a.activation:g}, threads {info['omp_threads']}")
    print("| method | alpha / mu | error / diagonal | time s (setup + solve) | iterations (CG) | converged |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        al = "-" if r["alpha"] is None else f"{r['alpha']:g}"
        its = f"{r['iterations']}" + (f" ({r['cg_iterations']})" if r["cg_iterations"] else "")
        print(f"| {r['method']} | {al} | {r['error']:.2e} | {r['time_s']:.2f} | {its} | "
              f"{'yes' if r['converged'] else 'no'} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"tets": len(scene.tets), "threads": info["omp_threads"], "blas": info["config"],
                       "rows": rows}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
