"""EMU at the strict tolerance on the bone scenes with and without recycled CG
directions (Solver(recycled_directions=N): directions of CG solves far longer
than the step before join the bone coarse space of the later steps).

    python bench/studies/recycling.py [--scenes realistic_biceps simple_joint_free ...] [--keep 4] [--alpha 100]
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
    ap.add_argument("--scenes", nargs="*", default=["realistic_biceps", "simple_joint_free", "big_muscle_free",
                                                    "arm_r5", "arm_r3", "neck_r2"])
    ap.add_argument("--keep", type=int, default=4)
    ap.add_argument("--alpha", type=float, default=100.0)
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}; "
          f"alpha {a.alpha:g} mu, strict tolerance\n")
    print(f"| scene | Newton / CG, off | s, off | Newton / CG, {a.keep} recycled | s, {a.keep} recycled | "
          "answers apart (of the diagonal) |")
    print("|---|---|---|---|---|---|")
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        off = emu.Solver(scene, "emu", alpha=a.alpha, error_estimate=False,
                         recycled_directions=0).solve(act, normalized=normalized)
        on = emu.Solver(scene, "emu", alpha=a.alpha, error_estimate=False,
                        recycled_directions=a.keep).solve(act, normalized=normalized)
        print(f"| {name} | {off.iterations} / {off.cg_iterations} | {off.time_s:.2f} | {on.iterations} / "
              f"{on.cg_iterations} | {on.time_s:.2f} | {emu.vertex_error(on, off):.1e} |", flush=True)


if __name__ == "__main__":
    main()
