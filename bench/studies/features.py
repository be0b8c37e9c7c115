"""A scene pays only for what it uses: setup and solve time, peak memory and
the structures built (Solver.structures()) of a pinned muscle against the same
scene with one feature switched on, and of the arm with its forearm fixed
against moving. Each case runs in its own process (peak RSS is per process).

    python bench/studies/features.py [--resolution 6] [--arm-resolution 4]
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

CASES = {
    "pinned muscle": "s = fusiform(R, tendon_fraction=0, warn=False); act = {'belly': 5e4}; kw = {}; load = {}",
    "+ tendons": "s = fusiform(R, warn=False); act = {'belly': 5e4}; kw = {}; load = {}",
    "+ gravity": "s = fusiform(R, tendon_fraction=0, warn=False); act = {'belly': 5e4}; kw = {}; "
                 "load = {'gravity': [0, -9.81, 0]}",
    "+ error estimate": "s = fusiform(R, tendon_fraction=0, warn=False); act = {'belly': 5e4}; "
                        "kw = {'error_estimate': True}; load = {}",
    "+ Schur preconditioner": "s = fusiform(R, tendon_fraction=0, warn=False); act = {'belly': 5e4}; "
                              "kw = {'preconditioner': 'schur'}; load = {}",
    "arm, forearm fixed": "s = arm(A, forearm_fixed=True); act = {'flexor': 0.3}; kw = {}; load = {'normalized': True}",
    "arm, forearm on its hinge": "s = arm(A); act = {'flexor': 0.3}; kw = {}; load = {'normalized': True}",
}

CHILD = """
import json, resource, time, warnings
warnings.simplefilter("ignore")
import emu
from emu.build.scenes import arm, fusiform
R, A = {r}, {a}
{case}
opts = dict(alpha=100.0, error_estimate=False, max_iterations=10)
opts.update(kw)
t0 = time.perf_counter()
solver = emu.Solver(s, "emu", **opts)
setup = time.perf_counter() - t0
sol = solver.solve(act, **load)
print(json.dumps(dict(tets=len(s.tets), setup=setup, solve=sol.solve_time_s, estimate=sol.error_estimate_time_s,
                      newton=sol.iterations, cg=sol.cg_iterations, structures=solver.structures(),
                      rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)))
"""


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=6)
    ap.add_argument("--arm-resolution", type=int, default=4)
    a = ap.parse_args(argv)
    print(f"{time.strftime('%Y-%m-%d')}; EMU at alpha = 100 mu, 10 Newton steps at most; peak RSS of the whole "
          "process (Python and numpy included)\n")
    print("| case | tets | setup s | solve s (+ estimate) | Newton / CG | peak RSS MB | structures (MB) |")
    print("|---|---|---|---|---|---|---|")
    for name, case in CASES.items():
        code = CHILD.format(r=a.resolution, a=a.arm_resolution, case=case)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        built = ", ".join(f"{k} {v / 1e6:.1f}" for k, v in r["structures"].items())
        est = f" (+ {r['estimate']:.2f})" if r["estimate"] else ""
        print(f"| {name} | {r['tets']} | {r['setup']:.2f} | {r['solve']:.2f}{est} | {r['newton']} / {r['cg']} | "
              f"{r['rss_mb']:.0f} | {built} |", flush=True)


if __name__ == "__main__":
    main()
