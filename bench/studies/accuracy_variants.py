"""EMU's accuracy mode (Solver(accuracy=...)) under Solver option variants:
per scene, Newton / CG counts, solve and estimate seconds, the alpha chosen,
the estimate and the true vertex error to the converged FEM answer; with
--demo also the demo's 25 warm-started frames (summed counts, largest error).
Options as in bench/studies/variants.py (one --variant per run, comma-separated
key=value pairs; an empty --variant '' is the defaults).

    python bench/studies/accuracy_variants.py --scenes fusiform_20k arm_r5 \\
        --variant cg_forcing_min=0 --variant '' [--demo [--demo-resolution 3 --demo-frames 25]] [--threads 1]
"""
from __future__ import annotations

import argparse
import warnings

import numpy as np

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run
from demo_phases import run_frames
from emu.app.demo import demo_spec
from variants import parse_variant


def scene_row(name, scene, act, normalized, fem, accuracy, variant) -> str:
    solver = emu.Solver(scene, "emu", **{"accuracy": accuracy, **variant})
    sol = solver.solve(act, normalized=normalized)
    return (f"| {name} | {sol.iterations} / {sol.cg_iterations} | {sol.solve_time_s:.2f} + {sol.error_estimate_time_s:.2f} | "
            f"{solver.alpha:.0f} ({sol.settings['alpha_attempts']}) | {sol.error_estimate:.2e} | "
            f"{emu.vertex_error(sol, fem):.2e} |")


def demo_row(spec, references, accuracy, variant) -> str:
    options = {**spec.solver, "accuracy": accuracy, **variant}
    r = run_frames(spec, options.pop("method", "emu"), references, **options)
    return (f"| demo ({spec.frames} frames) | {r['newton']} / {r['cg']} | {r['solve_s']:.2f} + {r['estimate_s']:.2f} "
            f"| | | {r['max_error']:.2e} |")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_20k", "simple_joint_free", "big_muscle_free", "arm_r5",
                                                    "neck_r2", "arm_r3", "realistic_biceps"])
    ap.add_argument("--variant", action="append", default=[], help="Solver options, e.g. cg_forcing_min=0")
    ap.add_argument("--accuracy", type=float, default=0.01)
    ap.add_argument("--demo", action="store_true", help="also the demo's frames")
    ap.add_argument("--demo-resolution", type=int, default=3)
    ap.add_argument("--demo-frames", type=int, default=25)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    variants = [parse_variant(v) for v in a.variant] or [{}]
    start_run(a.threads)
    warnings.simplefilter("ignore")
    refs = {}
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        refs[name] = (scene, act, normalized, emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized))
    if a.demo:
        spec = demo_spec(a.demo_resolution, a.demo_frames)
        fem = emu.Solver(spec.scene, "fem", rtol_grad=1e-9)
        demo_refs = [np.asarray(s.positions) for s in emu.solve_frames(fem, spec.frame_loads())]
    for variant in variants:
        print(f"\nvariant {variant or 'defaults'} (accuracy {a.accuracy:g}, {a.threads} thread(s))\n")
        print("| scene | Newton / CG | solve s + estimate s | alpha chosen (solves) | estimate | true error |")
        print("|---|---|---|---|---|---|")
        for name, (scene, act, normalized, fem) in refs.items():
            print(scene_row(name, scene, act, normalized, fem, a.accuracy, variant), flush=True)
        if a.demo:
            print(demo_row(spec, demo_refs, a.accuracy, variant), flush=True)


if __name__ == "__main__":
    main()
