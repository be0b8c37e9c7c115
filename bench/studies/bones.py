"""EMU against FEM on scenes with bones moved by the muscles.

For each scene: FEM (rigid bones, exponential-map Newton) and EMU
(Newton-Krylov) from rest at one activation; prints iterations, times, the
speed ratio, the moved bone's angle (or translation) from each and EMU's
vertex error to FEM over the bounding-box diagonal, as a Markdown table.

    python bench/studies/bones.py [--threads T] [--alpha A] [--arm-resolutions 3 5]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import emu
from emu.model.bones import bone_angle, bone_motion



def scenes(arm_res):
    yield ("simple_joint (bottom bone on the hinge)",
           emu.io.load_scene(emu.datasets.path("simple_joint"), free_bones=["bottom_bone"], warn=False),
           {"muscle": 1e4}, False, "bottom_bone")
    yield ("big_muscle (bone_2 free)",
           emu.io.load_scene(emu.datasets.path("big_muscle"), free_bones=["bone_2"], warn=False),
           {"muscle": 1e4}, False, "bone_2")
    for r in arm_res:
        yield (f"arm r={r} (forearm on the elbow hinge)", emu.scenes.arm(r), {"flexor": 0.45}, True, "forearm")
    yield ("neck r=2 (head on a ball joint)", emu.scenes.neck(2), {"left_front": 0.5}, True, "head")


def measure(scene, bone):
    return lambda sol: (bone_angle(scene, sol.positions, bone), bone_motion(scene, sol, bone).t)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--alpha", type=float, default=100.0)
    ap.add_argument("--arm-resolutions", type=int, nargs="*", default=[3, 5])
    args = ap.parse_args(argv)
    if args.threads:
        emu._core.set_threads(args.threads)
    info = emu.info()
    print(f"emu {info['version']}; BLAS {info['config']}; OpenMP threads {info['omp_threads']}; "
          f"alpha = {args.alpha:g} mu")
    print()
    print("| scene | tets | FEM s (it) | EMU s (it / CG) | FEM / EMU time | bone angle FEM / EMU (deg) | "
          "bone translation diff / diag | EMU vertex error / diag |")
    print("|---|---|---|---|---|---|---|---|")
    for name, scene, act, normalized, bone in scenes(args.arm_resolutions):
        res = {}
        for method in ("fem", "emu"):
            kw = {"alpha": args.alpha} if method == "emu" else {}
            t0 = time.perf_counter()
            solver = emu.Solver(scene, method, **kw)
            sol = solver.solve(act, normalized=normalized)
            wall = time.perf_counter() - t0
            if not sol.converged:
                print(f"<!-- {name} {method}: {sol.status} -->")
            res[method] = (sol, wall, *measure(scene, bone)(sol))
        fem, emu_ = res["fem"], res["emu"]
        diag = emu.bbox_diagonal(scene.points)
        err = emu.vertex_error(emu_[0], fem[0])
        dt = np.linalg.norm(emu_[3] - fem[3]) / diag
        print(f"| {name} | {len(scene.tets)} | {fem[1]:.2f} ({fem[0].iterations}) | "
              f"{emu_[1]:.2f} ({emu_[0].iterations} / {emu_[0].cg_iterations}) | {fem[1] / emu_[1]:.2f} | "
              f"{fem[2]:.2f} / {emu_[2]:.2f} | {dt:.1e} | {err:.1e} |", flush=True)


if __name__ == "__main__":
    main()
