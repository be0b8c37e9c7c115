"""Solver fingerprint: iteration counts, energies and positions of a fixed set
of solves (FEM and EMU; pinned, gravity, hinge, ball joint, free bone of a
research scene; Woodbury step; Schur preconditioner), for refactors that must
not change results.

    python bench/fingerprint.py OUT            # writes OUT.json and OUT.npz
    python bench/fingerprint.py OUT --compare BASE   # and prints the differences to BASE

A refactor that only moves code leaves every count and every position bit for
bit the same (same thread count, same BLAS).
"""
from __future__ import annotations

import argparse
import json

import numpy as np

import emu


def cases():
    fus = emu.scenes.fusiform(3, warn=False)
    yield "fusiform r=3", fus, {"belly": 5e4}, False, [
        ("fem", {}), ("emu", {}), ("emu", {"step": "woodbury", "max_iterations": 60}),
        ("emu", {"preconditioner": "schur"})]
    fus_g = emu.scenes.fusiform(3, warn=False)
    fus_g.gravity = [0.0, -9.81, 0.0]
    yield "fusiform r=3, gravity", fus_g, {"belly": 2e4}, False, [("fem", {}), ("emu", {})]
    sj = emu.io.load_scene(emu.datasets.path("simple_joint"), free_bones=["bottom_bone"], warn=False)
    yield "simple_joint, bottom bone free", sj, {"muscle": 1e4}, False, [("fem", {}), ("emu", {})]
    yield "arm r=3", emu.scenes.arm(3), {"flexor": 0.45}, True, [("fem", {}), ("emu", {})]
    yield "neck r=2", emu.scenes.neck(2), {"left_front": 0.5}, True, [("fem", {}), ("emu", {})]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--compare", default=None, help="a fingerprint written before (without extension)")
    args = ap.parse_args(argv)
    print(f"emu {emu.info()['version']}; BLAS {emu.info()['config']}; threads {emu.info()['omp_threads']}")
    stats, pos = {}, {}
    for name, scene, act, normalized, runs in cases():
        for method, kw in runs:
            key = f"{name} | {method} " + " ".join(f"{k}={v}" for k, v in kw.items())
            # EMU at a fixed alpha (100 mu): the strict tolerance, no accuracy-mode re-solves
            fixed = {"alpha": 100.0, "error_estimate": False} if method == "emu" else {}
            sol = emu.Solver(scene, method, **fixed, **kw).solve(act, normalized=normalized)
            stats[key] = dict(iterations=sol.iterations, cg=sol.cg_iterations, energy=sol.energy,
                              converged=sol.converged, status=sol.status, filtered=sol.filtered_steps,
                              solve_s=round(sol.time_s, 3))
            pos[key] = np.asarray(sol.positions)
            print(f"{key}: {sol.iterations} it / {sol.cg_iterations} CG, E = {sol.energy!r}, {sol.status}, "
                  f"{sol.time_s:.2f} s", flush=True)
    with open(args.out + ".json", "w") as f:
        json.dump(stats, f, indent=1)
    np.savez(args.out + ".npz", **{f"p{i}": pos[k] for i, k in enumerate(stats)}, keys=np.array(list(stats)))
    if not args.compare:
        return 0
    base = json.load(open(args.compare + ".json"))
    bpos = np.load(args.compare + ".npz")
    bkeys = list(bpos["keys"])
    same = True
    print("\n| solve | iterations / CG | energy | max position difference |\n|---|---|---|---|")
    for key, st in stats.items():
        if key not in base:
            print(f"| {key} | not in the base | | |")
            continue
        b = base[key]
        dx = float(np.abs(bpos[f"p{bkeys.index(key)}"] - pos[key]).max())
        same &= b["iterations"] == st["iterations"] and b["cg"] == st["cg"] and dx == 0.0
        print(f"| {key} | {b['iterations']} / {b['cg']} -> {st['iterations']} / {st['cg']} | "
              f"{b['energy']!r} -> {st['energy']!r} | {dx:.1e} |")
    print("\nidentical" if same else "\nDIFFERENT")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
