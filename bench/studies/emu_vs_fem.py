#!/usr/bin/env python3
"""EMU against the FEM reference on the procedural fusiform muscle.

    python bench/studies/emu_vs_fem.py --tets 20000 [--threads 2] [--alpha 100] [--json out.json]

Runs FEM Newton and EMU (both step types) on the same scene and activation;
prints and writes as JSON: sizes, threads, BLAS, setup and solve seconds per
method, iterations (and CG iterations), final relative energy change, and
each EMU variant's vertex error to FEM (largest vertex distance over the
bounding-box diagonal). Timings are wall-clock on a shared machine: read
ratios, not absolute numbers.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time

import emu


def build_scene(tets: int):
    """The built-in fusiform muscle (emu.scenes.fusiform), proximal end pinned."""
    return emu.scenes.fusiform(tets=tets, pins=("proximal",))


def run(method, scene, activation, **kw):
    t0 = time.perf_counter()
    solver = emu.Solver(scene, method, **kw)
    sol = solver.solve(activation)
    wall = time.perf_counter() - t0
    return sol, wall


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tets", type=int, default=5000, help="approximate tet count of the fusiform muscle")
    ap.add_argument("--threads", type=int, default=None, help="OpenMP/OpenBLAS threads (default: as set)")
    ap.add_argument("--activation", type=float, default=5e4, help="absolute activation a of the belly")
    ap.add_argument("--alpha", type=float, default=100.0, help="EMU alpha relative to the muscle shear modulus")
    ap.add_argument("--modes", type=int, default=24)
    ap.add_argument("--woodbury-max-iterations", type=int, default=3000,
                    help="cap for the paper's quasi-Newton step (it may need thousands)")
    ap.add_argument("--skip-woodbury", action="store_true", help="do not run the paper's quasi-Newton step")
    ap.add_argument("--schur", action="store_true",
                    help="also run Newton-Krylov with the Schur-complement preconditioner")
    ap.add_argument("--json", type=str, default=None, help="write the results here")
    a = ap.parse_args(argv)
    if a.threads:
        emu._core.set_threads(a.threads)
    scene = build_scene(a.tets)
    act = {"belly": a.activation}
    info = emu.info()
    out = {
        "tets": int(len(scene.tets)), "vertices": int(len(scene.points)),
        "threads": info["omp_threads"], "blas_threads": info["blas_threads"],
        "blas": info["config"], "blas_library": info["library"], "machine": platform.processor() or platform.machine(),
        "activation": a.activation, "alpha": a.alpha, "modes": a.modes, "date": time.strftime("%Y-%m-%d"),
    }
    print(f"fusiform muscle: {out['tets']} tets, {out['vertices']} vertices; threads {out['threads']}; "
          f"BLAS {out['blas']}", flush=True)
    fem, fem_wall = run("fem", scene, act)
    rows = [("fem", fem, fem_wall)]
    variants = [("emu_newton_krylov", dict(step="newton-krylov"))]
    if a.schur:
        variants.append(("emu_newton_krylov_schur", dict(step="newton-krylov", preconditioner="schur")))
    if not a.skip_woodbury:
        variants.append(("emu_woodbury", dict(step="woodbury", max_iterations=a.woodbury_max_iterations)))
    for key, kw in variants:
        sol, wall = run("emu", scene, act, alpha=a.alpha, modes=a.modes, **kw)
        rows.append((key, sol, wall))
    print(f"{'method':<20}{'setup s':>9}{'solve s':>9}{'iters':>7}{'CG':>7}{'conv':>6}{'rel dE':>10}"
          f"{'|g|/|g0|':>10}{'err/diag':>10}{'speed-up':>9}")
    for key, sol, wall in rows:
        err = 0.0 if key == "fem" else emu.vertex_error(sol, fem)
        speed = (fem.time_s + fem.setup_time_s) / (sol.time_s + sol.setup_time_s)
        gr = sol.grad_norm / sol.grad_norm0 if sol.grad_norm0 else 0.0
        out[key] = {
            "setup_s": sol.setup_time_s, "solve_s": sol.time_s, "wall_s": wall, "iterations": sol.iterations,
            "cg_iterations": sol.cg_iterations, "converged": sol.converged, "status": sol.status,
            "rel_energy_change": sol.rel_energy_change, "rel_grad_norm": gr,
            "vertex_error_to_fem": err, "speedup_vs_fem": speed,
        }
        print(f"{key:<20}{sol.setup_time_s:>9.3f}{sol.time_s:>9.3f}{sol.iterations:>7}{sol.cg_iterations:>7}"
              f"{'yes' if sol.converged else 'NO':>6}{sol.rel_energy_change:>10.1e}{gr:>10.1e}{err:>10.2e}"
              f"{speed:>9.2f}", flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)
    return out


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
