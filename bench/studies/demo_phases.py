"""Where the time of ``emu demo`` goes: the demo's frames (the procedural arm,
flexor then extensor, each frame warm-started from the last) solved by FEM
and by EMU with the demo's settings (accuracy 0.01), each phase summed over
the frames (Solution.phase_times), with Newton / CG counts and EMU's error
estimate time (which the demo adds to EMU's total).

    python bench/studies/demo_phases.py [--resolution 3] [--frames 25] [--threads 1]
"""
from __future__ import annotations

import argparse

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import start_run
from emu.app.demo import demo_spec

PHASES = ("hessian", "preconditioner", "linear_solve", "line_search", "step", "other")  # Solution.phase_times


def run_frames(spec, method: str, references=None, **options) -> dict:
    """One method over the spec's frames, each warm-started from the last:
    summed times, counts and phases; with references (one #V by 3 array of
    positions per frame) also the largest vertex error to them (max_error)."""
    solver = emu.Solver(spec.scene, method, **options)
    totals = dict(solve_s=0.0, estimate_s=0.0, newton=0, cg=0, corrected=0, **{p: 0.0 for p in PHASES})
    errors = []
    for k, sol in enumerate(emu.solve_frames(solver, spec.frame_loads())):
        if references is not None:
            errors.append(emu.vertex_error(sol.positions, references[k]))
        totals["solve_s"] += sol.solve_time_s
        totals["estimate_s"] += sol.error_estimate_time_s
        totals["newton"] += sol.iterations
        totals["cg"] += sol.cg_iterations
        totals["corrected"] += int(sol.corrected)
        for p in PHASES:
            totals[p] += sol.phase_times[p]
    # the error estimate's FEM factorisations (its corrections run PCG on the last one first)
    totals["estimate_factorizations"] = getattr(solver._estimator.fem, "factorizations", None)
    if errors:
        totals["max_error"] = max(errors)
    return totals


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=3)
    ap.add_argument("--frames", type=int, default=25)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    spec = demo_spec(a.resolution, a.frames)
    print(f"demo arm, resolution {a.resolution}: {len(spec.scene.tets)} tets, {a.frames} frames, "
          f"{a.threads} thread(s)")
    print("| method | Newton / CG | solve s | + estimate s | " + " | ".join(PHASES) + " |")
    print("|---|---|---|---|" + "---|" * len(PHASES))
    rows = {}
    for method in ("fem", "emu"):
        options = dict(spec.solver) if method == "emu" else {}
        options.pop("method", None)
        r = rows[method] = run_frames(spec, method, **options)
        cells = " | ".join(f"{r[p]:.3f}" for p in PHASES)
        print(f"| {method} | {r['newton']} / {r['cg']} | {r['solve_s']:.2f} | {r['estimate_s']:.2f} | {cells} |")
    emu_total = rows["emu"]["solve_s"] + rows["emu"]["estimate_s"]
    print(f"EMU total (solve + estimates) / FEM: {emu_total / rows['fem']['solve_s']:.2f} "
          f"({rows['emu']['corrected']} of {a.frames} EMU frames FEM-corrected; the estimates factorised "
          f"{rows['emu']['estimate_factorizations']} times)")


if __name__ == "__main__":
    main()
