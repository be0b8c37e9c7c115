"""A sweep's wall time on a 2-worker Dask local cluster against the same
cases run one after another in this process (no Dask), 1 solver thread per
case, so both use the same per-case work and the cluster uses both cores.

    python bench/studies/sweep.py [--cases 8] [--resolution 3] [--frames 12] [--out /tmp/emu_sweep_bench]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import time

import emu
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import start_run
from emu.app.sweep import case_id, load_sweep, run_case

SCENE = """
[mesh.arm]
resolution = {resolution}
[solver]
method = "emu"
[frames]
count = {frames}
dt = 0.2
[activation.flexor]
keys = [[0.0, 0.0], [1.0, 0.6]]
interpolation = "smooth"
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=8)
    ap.add_argument("--resolution", type=int, default=3)
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--out", default="/tmp/emu_sweep_bench")
    args = ap.parse_args()
    start_run(1)
    shutil.rmtree(args.out, ignore_errors=True)
    os.makedirs(args.out)
    with open(os.path.join(args.out, "arm.toml"), "w") as f:
        f.write(SCENE.format(resolution=args.resolution, frames=args.frames))
    youngs = [2e4 + 1e4 * i for i in range(args.cases)]
    with open(os.path.join(args.out, "sweep.toml"), "w") as f:
        f.write(f'base = "arm.toml"\nplot = "angle:forearm"\n[grid]\n"materials.flexor.youngs" = {json.dumps(youngs)}\n')
    spec = load_sweep(os.path.join(args.out, "sweep.toml"))
    t0 = time.perf_counter()
    seq = [run_case(spec["base"], c, os.path.join(args.out, "seq", f"case_{case_id(c)}"), spec["plot"], 1)
           for c in spec["cases"]]
    t_seq = time.perf_counter() - t0
    t0 = time.perf_counter()
    par = emu.sweep(os.path.join(args.out, "sweep.toml"), os.path.join(args.out, "dask"), workers=2, threads=1,
                    progress=lambda *a: None)
    t_par = time.perf_counter() - t0
    same = all(abs(float(a["plot_value"]) - float(b["plot_value"])) < 1e-9
               for a, b in zip(sorted(seq, key=lambda r: r["case"]), sorted(par, key=lambda r: r["case"])))
    print(f"{args.cases} cases (arm r={args.resolution}, {args.frames} frames, EMU, 1 solver thread each), "
          f"{os.cpu_count()} cores:")
    print("| run | wall s | per case s | speed-up |")
    print("|---|---|---|---|")
    print(f"| one after another (no Dask) | {t_seq:.2f} | {t_seq / args.cases:.2f} | 1.00 |")
    print(f"| Dask local cluster, 2 workers (start-up included) | {t_par:.2f} | {t_par / args.cases:.2f} | "
          f"{t_seq / t_par:.2f} |")
    print(f"\nsame answers (last-frame elbow angle) both ways: {same}")


if __name__ == "__main__":
    main()
