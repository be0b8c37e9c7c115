"""The hard case of EMU's error estimate: big_muscle with both bones fixed
(isometric) under strong activation (docs/DESIGN.md, "Where the estimate
fails").

Part 1, per activation a: EMU with accuracy 0.01 from rest against FEM to a
tight tolerance: alpha chosen, estimate, true error, FEM's Newton steps.
Part 2, at --activation: EMU at fixed alphas, the true error and estimate,
FEM's Newton steps from EMU's answer to FEM's equilibrium (and whether it is
the same: the energy), and how far along the way one exact Newton step of
FEM from EMU's answer gets (1 in a quadratic valley, 1/3 in a quartic one).

    python bench/studies/hard_isometric.py [--activations 2e3 5e3 1e4 2e4] [--activation 2e4] [--alphas 10 100 1000 1e4]
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--activations", type=float, nargs="*", default=[2e3, 5e3, 1e4, 1.5e4, 2e4])
    ap.add_argument("--activation", type=float, default=2e4)
    ap.add_argument("--alphas", type=float, nargs="*", default=[10, 100, 1000, 1e4])
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}\n")
    scene, _, _ = SCENES["big_muscle_isometric"]()
    fem_solver = emu.Solver(scene, "fem", rtol_grad=1e-9)

    print("| a | FEM Newton steps | EMU alpha chosen (solves) | estimate | true error | estimate / true |")
    print("|---|---|---|---|---|---|")
    for act in a.activations:
        fem = fem_solver.solve({"muscle": act})
        sol = emu.Solver(scene, "emu", accuracy=0.01).solve({"muscle": act})
        true = emu.vertex_error(sol, fem)
        print(f"| {act:g} | {fem.iterations} | {sol.settings['alpha']:.0f} ({sol.settings['alpha_attempts']}) | "
              f"{sol.error_estimate:.2e} | {true:.2e} | {sol.error_estimate / true:.2f} |", flush=True)

    act = {"muscle": a.activation}
    fem = fem_solver.solve(act)
    load = fem_solver.load_case(act)
    print(f"\na = {a.activation:g}: FEM from rest {fem.iterations} Newton steps, energy {fem.energy:.8e}\n")
    print("| alpha / mu | true error | estimate | EMU solve s | FEM steps from EMU's answer | same energy | "
          "one exact FEM step / true |")
    print("|---|---|---|---|---|---|---|")
    for alpha in a.alphas:
        sol = emu.Solver(scene, "emu", alpha=alpha).solve(act)
        true = emu.vertex_error(sol, fem)
        back = fem_solver.solve(act, initial=sol.positions)
        same = abs(back.energy - fem.energy) <= 1e-9 * abs(fem.energy)
        exact = fem_solver._core.newton_correction(load, sol.positions, "exact", 1)
        print(f"| {alpha:g} | {true:.2e} | {sol.error_estimate:.2e} | {sol.time_s:.2f} | {back.iterations} | "
              f"{'yes' if same else f'no ({back.energy:.8e})'} | {emu.vertex_error(sol.positions, exact) / true:.2f} |",
              flush=True)


if __name__ == "__main__":
    main()
