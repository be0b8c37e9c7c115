"""Accuracy as the knob: the step-size stopping rule and accuracy= against the
strict tolerance, per scene, for both methods.

    python bench/studies/accuracy.py [--scenes fusiform_r3 simple_joint_free big_muscle_free arm_r3 neck_r2]
                             [--target 0.01] [--fractions 0.3 0.1 0.03]

Part 1 (--fractions): each method at a fixed alpha (300 mu for EMU) stopped
when a full step moves no vertex by more than fraction x target x diagonal:
iterations, seconds and the true vertex error to the converged FEM answer.
Part 2: Solver(accuracy=target) for both methods against the strict default
tolerance (EMU at alpha = 100 mu): seconds, alpha chosen (and how many
solves), the estimate and the true error.
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES
from emu import _core



def with_step_tol(solver, method, step_tol, alpha):
    o = _core.SolverOptions()
    o.step_tol = step_tol
    if method == "fem":
        return _core.FemSolver(solver.model, o)
    eo = _core.EmuSolverOptions()
    eo.alpha = alpha * solver.mu_ref
    return _core.EmuSolver(solver.model, o, eo)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_r3", "simple_joint_free", "big_muscle_free", "arm_r3",
                                                    "neck_r2"])
    ap.add_argument("--target", type=float, default=0.01)
    ap.add_argument("--fractions", type=float, nargs="*", default=[0.3, 0.1, 0.03])
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}; "
          f"target {a.target:g}")
    refs = {}
    print("\nStep-size rule (EMU at alpha = 300 mu): iterations / seconds / true error per fraction\n")
    print("| scene | method | strict | " + " | ".join(f"fraction {f:g}" for f in a.fractions) + " |")
    print("|---|---|---|" + "---|" * len(a.fractions))
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        fem = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
        refs[name] = (scene, act, normalized, fem)
        diag = emu.bbox_diagonal(scene.points)
        for method in ("fem", "emu"):
            kw = dict(alpha=300.0, error_estimate=False) if method == "emu" else {}
            solver = emu.Solver(scene, method, **kw)
            load = solver.load_case(act, normalized=normalized)
            cells = []
            for tol in [0.0] + [f * a.target * diag for f in a.fractions]:
                r = with_step_tol(solver, method, tol, 300.0).solve(load)
                err = emu.vertex_error(np.asarray(r.positions), fem.positions)
                cells.append(f"{r.iterations} / {r.time_s:.2f} / {err:.1e}")
            print(f"| {name} | {method} | " + " | ".join(cells) + " |", flush=True)
    print(f"\naccuracy = {a.target:g} against the strict tolerance (EMU strict at alpha = 100 mu)\n")
    print("| scene | FEM strict s (err) | FEM accuracy s (err) | EMU strict s (err) | EMU accuracy s + estimate s | "
          "alpha chosen (solves) | estimate | true error |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (scene, act, normalized, fem) in refs.items():
        fs = emu.Solver(scene, "fem").solve(act, normalized=normalized)
        fa = emu.Solver(scene, "fem", accuracy=a.target).solve(act, normalized=normalized)
        es = emu.Solver(scene, "emu", error_estimate=False).solve(act, normalized=normalized)
        ea = emu.Solver(scene, "emu", accuracy=a.target).solve(act, normalized=normalized)
        print(f"| {name} | {fs.time_s:.2f} ({emu.vertex_error(fs, fem):.0e}) | {fa.time_s:.2f} "
              f"({emu.vertex_error(fa, fem):.0e}) | {es.time_s:.2f} ({emu.vertex_error(es, fem):.1e}) | "
              f"{ea.solve_time_s:.2f} + {ea.error_estimate_time_s:.2f} | {ea.settings['alpha']:.0f} "
              f"({ea.settings['alpha_attempts']}) | {ea.error_estimate:.1e} | {emu.vertex_error(ea, fem):.1e} |",
              flush=True)


if __name__ == "__main__":
    main()
