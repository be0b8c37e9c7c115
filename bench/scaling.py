"""Scaling with mesh size: FEM and EMU on the fusiform muscle and the arm.

For each scene and size, in separate processes (so each peak RSS is the
method's own): FEM to a tight tolerance, its iterates recorded (the last one
is the reference); then EMU with its defaults (accuracy 0.01). Per method:
setup seconds, seconds to reach and stay within 1% of the reference, seconds
to its own convergence, iterations (CG), peak RSS; then log-log slopes of
time against tets and one PNG.

    python bench/scaling.py [--fusiform 3000 20000 80000 300000 600000] [--arm 3 5 7 9] [--out bench/scaling]
    python bench/scaling.py --fusiform 1500 3000 --arm 1 2      # the small version (tests/test_bench.py)
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def build(scene, size):
    import emu

    if scene == "fusiform":
        return emu.scenes.fusiform(tets=int(size), warn=False), {"belly": 5e4}, False
    return emu.scenes.arm(int(size)), {"flexor": 0.45}, True


def child(scene, size, method, ref_path):
    """One method on one mesh, in this process; prints a JSON line."""
    import emu

    warnings.simplefilter("ignore")
    s, act, normalized = build(scene, size)
    t0 = time.perf_counter()
    solver = emu.Solver(s, "fem", rtol_grad=1e-9) if method == "fem" else emu.Solver(s, "emu")
    setup = time.perf_counter() - t0
    sol = solver.solve(act, normalized=normalized, record_iterates=True)
    if method == "fem":
        np.save(ref_path, sol.positions)
    ref = np.load(ref_path)
    out = {"scene": scene, "size": size, "tets": len(s.tets), "vertices": len(s.points), "method": method,
           "setup_s": setup, "solve_s": sol.time_s, "iterations": sol.iterations, "cg": sol.cg_iterations,
           "converged": sol.converged, "to_1pct_s": setup + emu.time_to_error(sol, ref, 0.01),
           "to_converged_s": setup + sol.time_s,
           "error": emu.vertex_error(sol, ref), "alpha": sol.settings.get("alpha"),
           "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
    print(json.dumps(out), flush=True)


def slope(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(y) & (y > 0)
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0]) if ok.sum() >= 2 else float("nan")


def plot(path, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5))
    for scene, marker in (("fusiform", "o"), ("arm", "s")):
        for method, color in (("fem", "k"), ("emu", "tab:blue")):
            r = [x for x in rows if x["scene"] == scene and x["method"] == method]
            if not r:
                continue
            n = [x["tets"] for x in r]
            label = f"{method.upper()} {scene}"
            axes[0].loglog(n, [x["to_1pct_s"] for x in r], marker=marker, color=color, label=label)
            axes[1].loglog(n, [x["to_converged_s"] for x in r], marker=marker, color=color, label=label)
            axes[2].loglog(n, [x["peak_rss_mb"] for x in r], marker=marker, color=color, label=label)
    for ax, title in zip(axes, ("seconds to 1% of FEM's answer", "seconds to convergence (EMU: accuracy 0.01)",
                                "peak RSS (MB)")):
        ax.set_xlabel("tets")
        ax.set_title(title)
        ax.legend(fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--fusiform", type=int, nargs="*", default=[3000, 20000, 80000, 300000, 600000])
    ap.add_argument("--arm", type=int, nargs="*", default=[3, 5, 7, 9])
    ap.add_argument("--out", default=os.path.join(HERE, "scaling"))
    ap.add_argument("--child", nargs=4, metavar=("SCENE", "SIZE", "METHOD", "REF"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        child(a.child[0], int(a.child[1]), a.child[2], a.child[3])
        return 0
    os.makedirs(a.out, exist_ok=True)
    import emu

    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}")
    rows = []
    cases = [("fusiform", n) for n in a.fusiform] + [("arm", r) for r in a.arm]
    for scene, size in cases:
        ref = os.path.join(a.out, f"ref_{scene}_{size}.npy")
        for method in ("fem", "emu"):
            cmd = [sys.executable, os.path.abspath(__file__), "--child", scene, str(size), method, ref]
            p = subprocess.run(cmd, capture_output=True, text=True)
            if p.returncode != 0:
                print(f"{scene} {size} {method}: failed ({p.returncode}): {p.stderr.strip().splitlines()[-1:]}",
                      flush=True)
                break
            row = json.loads(p.stdout.strip().splitlines()[-1])
            rows.append(row)
            print(f"{scene} {size} {method}: {row['tets']} tets, to 1% {row['to_1pct_s']:.2f} s, converged "
                  f"{row['to_converged_s']:.2f} s, {row['iterations']} it ({row['cg']} CG), "
                  f"{row['peak_rss_mb']:.0f} MB", flush=True)
        if os.path.exists(ref):
            os.remove(ref)
    with open(os.path.join(a.out, "scaling.json"), "w") as f:
        json.dump(rows, f, indent=1)
    plot(os.path.join(a.out, "scaling.png"), rows)
    print("\n| scene | tets | FEM setup s | FEM to 1% s | FEM converged s (it) | FEM MB | EMU setup s | EMU to 1% s | "
          "EMU converged s (it / CG) | EMU MB | alpha | FEM / EMU to 1% |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for scene, size in cases:
        f = [x for x in rows if x["scene"] == scene and x["size"] == size and x["method"] == "fem"]
        e = [x for x in rows if x["scene"] == scene and x["size"] == size and x["method"] == "emu"]
        if not f or not e:
            continue
        f, e = f[0], e[0]
        print(f"| {scene} | {f['tets']} | {f['setup_s']:.2f} | {f['to_1pct_s']:.2f} | {f['to_converged_s']:.2f} "
              f"({f['iterations']}) | {f['peak_rss_mb']:.0f} | {e['setup_s']:.2f} | {e['to_1pct_s']:.2f} | "
              f"{e['to_converged_s']:.2f} ({e['iterations']} / {e['cg']}) | {e['peak_rss_mb']:.0f} | "
              f"{e['alpha']:.0f} | {f['to_1pct_s'] / e['to_1pct_s']:.1f}x |")
    print("\nlog-log slopes of time against tets:")
    for scene in ("fusiform", "arm"):
        for method in ("fem", "emu"):
            r = [x for x in rows if x["scene"] == scene and x["method"] == method]
            if len(r) >= 2:
                n = [x["tets"] for x in r]
                print(f"  {scene} {method}: to 1% {slope(n, [x['to_1pct_s'] for x in r]):.2f}, converged "
                      f"{slope(n, [x['to_converged_s'] for x in r]):.2f}, RSS {slope(n, [x['peak_rss_mb'] for x in r]):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
