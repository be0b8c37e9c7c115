"""emu's default threads on a busy machine: scene files' first frames solved
by EMU and FEM (accuracy 0.01, warm-started), on a quiet machine and with
busy processes (a CPU hog per core, or one), with the threads left automatic
(emu.runtime: every core, fewer where other processes hold them), forced to
every core (today's OpenMP default before the automatic count), and one.

    python bench/studies/threads_under_load.py [SCENE.toml ...] [--frames 9] [--hogs all 1]

Prints one table; the ratios the issue asks for: automatic over one thread
under load (target <= 1.3), automatic over every core on a quiet machine
(target <= 1, within the machine's noise). docs/DESIGN.md, "Threads on a
busy machine", quotes it.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import warnings

import emu
from emu.app.scenefile import load_scene_file

HERE = os.path.dirname(os.path.abspath(__file__))


def run(spec, method, frames, mode) -> tuple:
    """Seconds for the first frames and the thread counts the solves ran on."""
    emu.runtime.set_threads(None if mode == "auto" else mode)
    solver = emu.Solver(spec.scene, method, accuracy=0.01)
    t0 = time.perf_counter()
    used = [s.settings["threads"] for s in emu.solve_frames(solver, spec.frame_loads(range(min(frames, spec.frames))))]
    return time.perf_counter() - t0, sorted(set(used))


def hogs(n):
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=[os.path.join(HERE, "..", "..", "examples", f)
                                                   for f in ("neck_roll.toml", "arm_flex_extend.toml")])
    ap.add_argument("--frames", type=int, default=9)
    ap.add_argument("--hogs", nargs="*", default=["all", "1"], help="busy processes: 'all' (one per core) or a count")
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    cores = len(os.sched_getaffinity(0))
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; {cores} cores; threads {i['threads']}; "
          f"{time.strftime('%Y-%m-%d')}\n")
    print("| scene | method | load | automatic s (threads) | every core s | one thread s | automatic / one | "
          "automatic / every core |")
    print("|---|---|---|---|---|---|---|---|")
    loads = [("quiet", 0)] + [(f"{cores if h == 'all' else int(h)} busy", cores if h == "all" else int(h))
                              for h in a.hogs]
    for path in a.scenes:
        spec = load_scene_file(path)
        for method in ("emu", "fem"):
            run(spec, method, 2, 1)   # warm: imports, first factorisation's allocations
            for name, n in loads:
                procs = hogs(n)
                try:
                    time.sleep(0.5 if n else 0.0)
                    auto, used = run(spec, method, a.frames, "auto")
                    every, _ = run(spec, method, a.frames, cores)
                    one, _ = run(spec, method, a.frames, 1)
                finally:
                    for p in procs:
                        p.kill()
                print(f"| {os.path.basename(path)} | {method} | {name} | {auto:.2f} ({'/'.join(map(str, used))}) | "
                      f"{every:.2f} | {one:.2f} | {auto / one:.2f} | {auto / every:.2f} |", flush=True)
    emu.runtime.set_threads(None)


if __name__ == "__main__":
    main()
