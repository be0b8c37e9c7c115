"""Error against run time for FEM and EMU, per scene.

Each method's iterates are recorded (Solver.solve(record_iterates=True)) and
their vertex error to the converged FEM answer is plotted against time
(setup + solve seconds, log-log): FEM's curve (a factorisation per Newton
step), FEM Newton-CG on a lagged factor (lagged_factor=True: the stronger
baseline), EMU's for alpha over two decades (k = 24 modes) and for k in
{12, 24, 48, 96} at one alpha. The Pareto front (the lowest error any method
has reached by each time) is marked, and a table gives the time each method
needs to reach (and stay within) 2%, 1% and 0.5%, with the ratios FEM / best
EMU and lagged FEM / best EMU.

    python bench/error_vs_time.py [--scenes fusiform_20k simple_joint_free big_muscle_free arm_r5 neck_r2]
                                  [--out bench/error_vs_time] [--threads T]
"""
from __future__ import annotations

import argparse
import json
import os
import time
import warnings

import numpy as np

import emu
from bench_scenes import SCENES
from emu.core.geometry import time_within

TARGETS = (0.02, 0.01, 0.005)


def curve(scene, method, act, normalized, fem, **kw):
    """(label, times (setup + solve), errors, solution) of one recorded solve."""
    t0 = time.perf_counter()
    solver = emu.Solver(scene, method, **kw)
    setup = time.perf_counter() - t0
    sol = solver.solve(act, normalized=normalized, record_iterates=True)
    t, e = emu.error_history(sol, fem)
    return setup + t, e, sol


def pareto(curves):
    """The lowest error reached by any curve by each time: (times, errors)."""
    pts = sorted((ti, ei) for t, e in curves for ti, ei in zip(t, e))
    ts, es, best = [], [], np.inf
    for ti, ei in pts:
        if ei < best:
            best = ei
            ts.append(ti)
            es.append(ei)
    return np.array(ts), np.array(es)


def plot(path, name, runs, front):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for label, t, e in runs:
        style = (dict(color="k", lw=2.2) if label == "FEM" else dict(color="k", lw=1.6, ls="--")
                 if label.startswith("FEM") else dict(lw=1.2, alpha=0.85))
        ax.loglog(t, np.maximum(e, 1e-9), marker=".", ms=4, label=label, **style)
    ax.step(front[0], np.maximum(front[1], 1e-9), where="post", color="red", lw=3, alpha=0.3, label="Pareto front")
    for target in TARGETS:
        ax.axhline(target, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("seconds (setup + solve)")
    ax.set_ylabel("vertex error to converged FEM / diagonal")
    ax.set_ylim(1e-5, 1.0)
    ax.set_title(f"{name}: error against run time")
    ax.legend(fontsize=7, ncol=2, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def scene_runs(a, scene, act, normalized) -> list:
    """[(label, times, errors)] of FEM, lagged FEM and EMU at every alpha and modes count, each
    against strict FEM's answer."""
    fem = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
    runs = [("FEM", *curve(scene, "fem", act, normalized, fem)[:2]),
            ("FEM lagged-CG", *curve(scene, "fem", act, normalized, fem, lagged_factor=True)[:2])]
    for alpha in a.alphas:
        t, e, _ = curve(scene, "emu", act, normalized, fem, alpha=alpha, error_estimate=False)
        runs.append((f"EMU alpha {alpha:g} k 24", t, e))
    for k in a.modes:
        t, e, _ = curve(scene, "emu", act, normalized, fem, alpha=a.modes_alpha, modes=k, error_estimate=False)
        runs.append((f"EMU alpha {a.modes_alpha:g} k {k}", t, e))
    return runs


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_20k", "simple_joint_free", "big_muscle_free", "arm_r5",
                                                    "neck_r2"])
    ap.add_argument("--alphas", type=float, nargs="*", default=[10, 30, 100, 300, 1000])
    ap.add_argument("--modes", type=int, nargs="*", default=[12, 48, 96])
    ap.add_argument("--modes-alpha", type=float, default=300.0)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "error_vs_time"))
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args(argv)
    if a.threads:
        emu.runtime.set_threads(a.threads)
    warnings.simplefilter("ignore")
    os.makedirs(a.out, exist_ok=True)
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}")
    rows, summary = [], {}
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        runs = scene_runs(a, scene, act, normalized)
        front = pareto([(t, e) for _, t, e in runs])
        png = os.path.join(a.out, f"{name}.png")
        plot(png, f"{name} ({len(scene.tets)} tets)", runs, front)
        fem_t = [time_within(runs[0][1], runs[0][2], g) for g in TARGETS]
        lagged_t = [time_within(runs[1][1], runs[1][2], g) for g in TARGETS]
        best = []
        for g in TARGETS:
            times = [(time_within(t, e, g), label) for label, t, e in runs[2:]]
            best.append(min(times))
        summary[name] = {"tets": len(scene.tets), "fem": fem_t, "fem_lagged": lagged_t,
                         "emu_best": [b[0] for b in best],
                         "emu_best_run": [b[1] for b in best],
                         "curves": {label: [t.tolist(), e.tolist()] for label, t, e in runs}}
        cells = []
        for g, ft, lt, (bt, bl) in zip(TARGETS, fem_t, lagged_t, best):
            ratio = ft / bt if np.isfinite(bt) and bt > 0 else 0.0
            lratio = lt / bt if np.isfinite(bt) and bt > 0 else 0.0
            cells.append(f"{ft:.2f} / {lt:.2f} / {bt:.2f} ({bl.replace('EMU ', '')}) / {ratio:.1f}x / {lratio:.1f}x")
        rows.append(f"| {name} | {len(scene.tets)} | " + " | ".join(cells) + " |")
        print(f"{name}: wrote {png}", flush=True)
    print("\nTime (s, setup + solve) to reach and stay within the error: FEM / lagged FEM / best EMU (its run) / "
          "FEM over EMU / lagged FEM over EMU\n")
    print("| scene | tets | " + " | ".join(f"{100 * g:g}%" for g in TARGETS) + " |")
    print("|---|---|" + "---|" * len(TARGETS))
    print("\n".join(rows))
    # the scenes of earlier runs stay (the README's table takes two runs: the
    # six scenes, then fusiform_80k at two alphas)
    path = os.path.join(a.out, "summary.json")
    if os.path.exists(path):
        with open(path) as f:
            summary = {**json.load(f), **summary}
    with open(path, "w") as f:
        json.dump(summary, f)


if __name__ == "__main__":
    main()
