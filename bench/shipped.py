"""What a user gets: each method as shipped, in a fresh process, timed as a
user would time it (wall clock of `emu.Solver(...)` plus `solve`, the error
estimate and every re-solve included) at `accuracy=` (0.01 by default), and
each answer checked against a strict FEM solve (|g| <= 1e-9 |g0|).

Methods: FEM Newton (a factorisation per step), FEM Newton-CG on a lagged
factor, both with `accuracy=` (the same step-size stop as EMU's), and EMU
with its defaults. Single solves from rest and, with --frames N, sequences:
the scene's activation along a bell curve over N frames, each frame
warm-started from the last (time per frame once warm: frames 2..N). Each
run is its own process, so its peak RSS is its own (the scene alone is
printed beside it).

    python bench/shipped.py [--scenes fusiform_6k arm_r5 ...] [--threads 1 2] [--accuracy 0.01 0.005]
                            [--frames 25] [--dynamics 0.0417] [--hindsight] [--out bench/shipped]

--dynamics DT (with --frames) makes every frame a BDF2 time step of DT seconds
with inertia (emu.Dynamics): the errors are then the distance between each
method's trajectory and strict FEM's (both from rest, each on its own path).

--hindsight adds EMU's bound: the fastest of its runs at alpha = 30-1000 mu
(estimate off) to the first iterate from which it stays within the accuracy
of the strict answer, which no user can run (it needs the answer).
Results also go to OUT/shipped.json.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
METHODS = {"fem": dict(method="fem"), "fem_lagged": dict(method="fem", lagged_factor=True),
           "emu": dict(method="emu")}
HINDSIGHT_ALPHAS = (30, 100, 300, 1000)


def _rss_mb(field: str) -> float:
    """VmHWM (peak) or VmRSS of this process, MB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def frame_activations(act: dict, frames: int) -> list:
    """The scene's activation along a bell curve: sin(pi (f + 1) / (frames + 1)) per frame."""
    return [{k: v * math.sin(math.pi * (f + 1) / (frames + 1)) for k, v in act.items()} for f in range(frames)]


def child(a) -> None:
    """One method's run in this process: prints one JSON line, saves positions to a.positions."""
    import warnings

    import emu
    from bench_scenes import SCENES

    warnings.simplefilter("ignore")
    emu.runtime.set_threads(a.threads)
    scene, act, normalized = SCENES[a.scene]()
    scene_rss = _rss_mb("VmHWM")
    frames = frame_activations(act, a.frames) if a.frames else [act]
    out = {"scene": a.scene, "tets": len(scene.tets), "method": a.method, "threads": a.threads,
           "accuracy": a.accuracy, "frames": a.frames, "scene_rss_mb": scene_rss}
    loads = [emu.Frame(activation=f, normalized=normalized) for f in frames]
    dynamics = emu.Dynamics(a.dynamics) if a.dynamics else None
    if a.method == "reference":
        solver = emu.Solver(scene, "fem", rtol_grad=1e-9, lagged_factor=True)
        sols = [sol.positions for sol in emu.solve_frames(solver, loads, dynamics=dynamics)]
        np.save(a.positions, np.stack(sols))
        out["converged"] = all(True for _ in sols)
        print(json.dumps(out))
        return
    if a.method == "hindsight":
        ref = np.load(a.reference)[0]
        best = float("inf")
        for alpha in HINDSIGHT_ALPHAS:
            t0 = time.perf_counter()
            s = emu.Solver(scene, "emu", alpha=alpha, accuracy=a.accuracy, error_estimate=False)
            setup = time.perf_counter() - t0
            sol = s.solve(act, normalized=normalized, record_iterates=True)
            t, e = emu.error_history(sol, ref)
            best = min(best, setup + emu.geometry.time_within(t, e, a.accuracy))
        out["hindsight_s"] = best
        print(json.dumps(out))
        return
    t0 = time.perf_counter()
    options = dict(map(emu.options.parse_option, a.emu_option)) if a.method == "emu" else {}
    solver = emu.Solver(scene, **METHODS[a.method], accuracy=a.accuracy, **options)
    setup = time.perf_counter() - t0
    frame_s, positions, parts = [], [], []
    steps = emu.solve_frames(solver, loads, dynamics=dynamics)
    for _ in loads:
        t1 = time.perf_counter()
        prev = next(steps)
        frame_s.append(time.perf_counter() - t1)
        positions.append(prev.positions)
        parts.append({"estimate_s": prev.error_estimate_time_s, "iterations": prev.iterations,
                      "cg": prev.cg_iterations, "factorizations": prev.factorizations,
                      "attempts": prev.settings.get("alpha_attempts", 1), "alpha": prev.settings.get("alpha"),
                      "corrected": bool(prev.corrected), "converged": bool(prev.converged),
                      "estimate": prev.error_estimate})
    np.save(a.positions, np.stack(positions))
    out.update(setup_s=setup, frame_s=frame_s, parts=parts, peak_rss_mb=_rss_mb("VmHWM"))
    print(json.dumps(out))


def run_child(args: list) -> dict:
    p = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", *map(str, args)],
                       capture_output=True, text=True)
    if p.returncode != 0:
        return {"failed": (p.stderr.strip().splitlines() or ["(no output)"])[-1]}
    return json.loads(p.stdout.strip().splitlines()[-1])


def errors_to(ref: np.ndarray, x: np.ndarray) -> list:
    """Per frame: max vertex distance / the rest bounding-box diagonal (emu.vertex_error's measure)."""
    import emu
    return [emu.vertex_error(xi, ri) for xi, ri in zip(x, ref)]


def cell(r: dict, key: str) -> str:
    if "failed" in r:
        return f"failed: {r['failed'][:60]}"
    return f"{r[key]:.2f} ({max(r['errors']):.1e})"



def one_row(a, name: str, ref: dict, reference, ref_path: str, threads: int, accuracy: float, tmp: str) -> tuple:
    """(table cells, json row) of one scene at one thread count and accuracy: every method in
    its own process, errors to the reference, the faster FEM over EMU, the hindsight bound."""
    common = ["--scene", name, "--frames", a.frames, "--dynamics", a.dynamics]
    res = {}
    for m in METHODS:
        path = os.path.join(tmp, f"{name}_{m}.npy")
        r = run_child([*common, "--method", m, "--threads", threads, "--accuracy", accuracy,
                       "--positions", path, *[f"--emu-option={o}" for o in a.emu_option]])
        if "failed" not in r:
            r["errors"] = errors_to(reference, np.load(path))
            fs = r["frame_s"]
            r["total_s"] = r["setup_s"] + sum(fs)
            r["warm_frame_s"] = sum(fs[1:]) / (len(fs) - 1) if len(fs) > 1 else float("nan")
        res[m] = r
    key = "warm_frame_s" if a.frames else "total_s"
    fem_best = min((res[m][key] for m in ("fem", "fem_lagged") if "failed" not in res[m]), default=float("inf"))
    e = res["emu"]
    ratio = fem_best / e[key] if "failed" not in e else float("nan")
    emu_cell = cell(e, key)
    if "failed" not in e:
        parts = e["parts"]
        emu_cell += f" ({sum(p['attempts'] for p in parts)}, {sum(p['estimate_s'] for p in parts):.2f})"
    cells = [name, str(ref["tets"]), str(threads), f"{accuracy:g}", cell(res["fem"], key),
             cell(res["fem_lagged"], key), emu_cell, f"{ratio:.2f}x"]
    row = {"scene": name, "tets": ref["tets"], "threads": threads, "accuracy": accuracy,
           "frames": a.frames, "runs": res, "faster_fem_over_emu": ratio}
    if a.hindsight and not a.frames:
        h = run_child([*common, "--method", "hindsight", "--threads", threads, "--accuracy",
                       accuracy, "--reference", ref_path])
        hs = h.get("hindsight_s", float("nan"))
        row["hindsight_s"] = hs
        cells += [f"{hs:.2f}", f"{e.get(key, float('nan')) / hs:.1f}x"]
    rss = [f"{e.get('scene_rss_mb', float('nan')):.0f}"] + [
        f"{res[m].get('peak_rss_mb', float('nan')):.0f}" for m in METHODS]
    cells.append(", ".join(rss))
    return cells, row

def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=["fusiform_6k", "fusiform_20k", "arm_r3", "arm_r5",
                                                    "realistic_biceps", "simple_joint_free", "big_muscle_free",
                                                    "neck_r2"])
    ap.add_argument("--threads", type=int, nargs="*", default=[1])
    ap.add_argument("--accuracy", type=float, nargs="*", default=[0.01])
    ap.add_argument("--frames", type=int, default=0, help="sequences of this many frames (0: single solves)")
    ap.add_argument("--dynamics", type=float, default=0.0,
                    help="with --frames: each frame a BDF2 time step of this many seconds (0: equilibria)")
    ap.add_argument("--hindsight", action="store_true", help="EMU's hindsight bound (single solves)")
    ap.add_argument("--emu-option", action="append", default=[], metavar="NAME=VALUE",
                    help="an option for EMU's runs (e.g. joint_coordinates=False), as `emu run -O` takes it")
    ap.add_argument("--out", default=os.path.join(HERE, "shipped"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--scene", help=argparse.SUPPRESS)
    ap.add_argument("--method", help=argparse.SUPPRESS)
    ap.add_argument("--positions", help=argparse.SUPPRESS)
    ap.add_argument("--reference", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    sys.path.insert(0, HERE)
    if a.child:
        a.threads, a.accuracy = a.threads[0], a.accuracy[0]
        return child(a)
    import emu

    os.makedirs(a.out, exist_ok=True)
    info = emu.info()
    kind = (f"sequences of {a.frames} frames, seconds per frame once warm (frames 2..{a.frames})" if a.frames
            else "single solves from rest, seconds, setup included")
    if a.dynamics:
        kind += f"; BDF2 time steps of {a.dynamics:g} s (errors: trajectory to strict FEM's)"
    print(f"emu {info['version']}; BLAS {info['config']}; {time.strftime('%Y-%m-%d')}; {kind}; "
          "(largest vertex error to strict FEM / diagonal)\n")
    head = "| scene | tets | threads | accuracy | FEM | lagged FEM | EMU (attempts, estimate s) | faster FEM / EMU |"
    head += " EMU hindsight s | EMU / hindsight |" if a.hindsight and not a.frames else ""
    head += " peak RSS MB: scene, FEM, lagged, EMU |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1), flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.scenes:
            ref_path = os.path.join(tmp, f"{name}_ref.npy")
            common = ["--scene", name, "--frames", a.frames, "--dynamics", a.dynamics]
            ref = run_child([*common, "--method", "reference", "--positions", ref_path])
            if "failed" in ref:
                print(f"| {name} | reference failed: {ref['failed']} |", flush=True)
                continue
            reference = np.load(ref_path)
            for threads in a.threads:
                for accuracy in a.accuracy:
                    cells, row = one_row(a, name, ref, reference, ref_path, threads, accuracy, tmp)
                    print("| " + " | ".join(cells) + " |", flush=True)
                    rows.append(row)
    with open(os.path.join(a.out, "shipped.json" if not a.frames else "shipped_sequences.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
