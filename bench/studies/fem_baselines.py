"""The FEM baselines against each other, and both against EMU on a sequence.

1. One solve from rest to the strict tolerance per scene: FEM Newton with a
   factorisation per iteration against FEM Newton-CG on a lagged factor
   (Solver(method="fem", lagged_factor=True)) for a few PCG caps: Newton / CG
   iterations, factorisations, seconds, the distance between the answers.
2. The demo's 25-frame sequence (emu demo's arm, warm-started frames): EMU
   with the demo's settings (accuracy 0.01) against FEM strict, FEM with the
   lagged factor and FEM with accuracy 0.01, with each method's seconds per
   phase (Solution.phase_times) summed over the frames.

    python bench/studies/fem_baselines.py [--scenes fusiform_20k arm_r5 realistic_biceps simple_joint_free]
        [--caps 10 25 50] [--threads 1] [--frames 25] [--resolution 3]
"""
from __future__ import annotations

import argparse
import collections

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run
from emu.app.demo import demo_spec

PHASES = ("hessian", "preconditioner", "linear_solve", "line_search", "step", "other")


def single_solves(names, caps):
    print("| scene | FEM variant | Newton / CG | factorisations | solve s | answer apart (of the diagonal) |")
    print("|---|---|---|---|---|---|")
    for name in names:
        scene, act, normalized = SCENES[name]()
        direct = None
        for cap in [0] + list(caps):
            kw = dict(lagged_factor=True, lagged_cg_iterations=cap) if cap else {}
            sol = emu.Solver(scene, "fem", **kw).solve(act, normalized=normalized)
            direct = direct or sol
            label = f"lagged factor, PCG cap {cap}" if cap else "factorisation per iteration"
            apart = emu.vertex_error(sol.positions, direct.positions)
            state = "" if sol.converged else f" (NOT converged: {sol.status})"
            print(f"| {name} | {label} | {sol.iterations} / {sol.cg_iterations} | {sol.factorizations} | "
                  f"{sol.time_s:.3f}{state} | {apart:.1e} |", flush=True)


def sequence(frames, resolution):
    spec = demo_spec(resolution=resolution, frames=frames)
    emu_kw = {k: v for k, v in spec.solver.items() if k != "method"}
    variants = (("EMU (demo settings)", "emu", emu_kw), ("FEM", "fem", {}),
                ("FEM lagged factor", "fem", dict(lagged_factor=True)), ("FEM accuracy 0.01", "fem", dict(accuracy=0.01)))
    print(f"\nThe demo's sequence: {len(spec.scene.tets)} tets, {spec.frames} frames, warm-started\n")
    print("| method | solve s (+ estimate s) | Newton / CG | solves | factorisations | " + " | ".join(PHASES) + " |")
    print("|---|---|---|---|---|" + "---|" * len(PHASES))
    for label, method, kw in variants:
        solver = emu.Solver(spec.scene, method, **kw)
        total = collections.Counter()
        for sol in emu.solve_frames(solver, spec.frame_loads()):
            for p in PHASES:
                total[p] += sol.phase_times[p]
            total["solve"] += sol.solve_time_s
            total["estimate"] += sol.error_estimate_time_s
            total["newton"] += sol.iterations
            total["cg"] += sol.cg_iterations
            total["solves"] += sol.settings.get("alpha_attempts", 1)
            total["factorizations"] += sol.factorizations
        est = f" (+ {total['estimate']:.2f})" if method == "emu" else ""
        print(f"| {label} | {total['solve']:.2f}{est} | {total['newton']} / {total['cg']} | {total['solves']} | "
              f"{total['factorizations']} | " + " | ".join(f"{total[p]:.2f}" for p in PHASES) + " |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_20k", "arm_r5", "realistic_biceps", "simple_joint_free"])
    ap.add_argument("--caps", type=int, nargs="*", default=[10, 25, 50])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=25)
    ap.add_argument("--resolution", type=int, default=3)
    a = ap.parse_args(argv)
    start_run(a.threads)
    single_solves(a.scenes, a.caps)
    if a.frames > 0:
        sequence(a.frames, a.resolution)


if __name__ == "__main__":
    main()
