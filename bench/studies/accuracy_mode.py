"""Accuracy mode (what emu.solve does by default: an answer within 1% of
FEM's) against the FEM baselines, one solve from rest per scene: EMU
re-solving at a larger alpha where its estimate misses (fem_correction=False)
against EMU returning its answer corrected by two FEM Newton steps
(fem_correction=True, the default), FEM Newton and FEM with the lagged factor
to the strict tolerance and FEM with accuracy=0.01. Seconds are solve + error
estimate (EMU) or solve (FEM), 1 thread unless --threads; errors are to FEM
converged to |g| <= 1e-9 |g0|.

    python bench/studies/accuracy_mode.py [--scenes arm_r5 fusiform_20k realistic_biceps ...] [--target 0.01]
                                  [--emu-preconditioners constant-schur woodbury]

With several --emu-preconditioners, the EMU columns repeat per preconditioner
(same run: the comparison a default change needs).
"""
from __future__ import annotations

import argparse
import warnings

import emu
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run

DEFAULT_SCENES = ["fusiform_r3", "fusiform_20k", "arm_r3", "arm_r5", "neck_r2", "simple_joint_free",
                  "big_muscle_free", "realistic_biceps"]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="*", default=DEFAULT_SCENES, choices=list(SCENES))
    ap.add_argument("--target", type=float, default=0.01)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--emu-step-fraction", type=float, default=None,
                    help="EMU's accuracy stopping rule: a full step under this fraction of the target (default: the Solver's)")
    ap.add_argument("--emu-preconditioners", nargs="*", default=[None],
                    help="Newton-Krylov preconditioners for the EMU columns (default: the Solver's)")
    a = ap.parse_args(argv)
    start_run(a.threads)
    emu_cols = []
    for pc in a.emu_preconditioners:
        tag = "" if pc is None else f", {pc}"
        emu_cols += [f"EMU re-solving{tag} s (solves, error)",
                     f"EMU corrected{tag} s (solves, corrected, estimate, error)"]
    print("| scene | FEM s | FEM lagged s | FEM accuracy s (error) | " + " | ".join(emu_cols) + " |")
    print("|---|---|---|---|" + "---|" * len(emu_cols))
    for name in a.scenes:
        scene, act, normalized = SCENES[name]()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(act, normalized=normalized)
            fem = emu.Solver(scene, "fem").solve(act, normalized=normalized)
            lagged = emu.Solver(scene, "fem", lagged_factor=True).solve(act, normalized=normalized)
            fem_a = emu.Solver(scene, "fem", accuracy=a.target).solve(act, normalized=normalized)
            fraction = {} if a.emu_step_fraction is None else {"step_fraction": a.emu_step_fraction}
            runs = []
            for pc in a.emu_preconditioners:
                opts = dict(fraction, **({} if pc is None else {"preconditioner": pc}))
                runs.append([emu.Solver(scene, "emu", accuracy=a.target, fem_correction=c, **opts)
                             .solve(act, normalized=normalized) for c in (False, True)])
        cells = [f"{fem.time_s:.2f}", f"{lagged.time_s:.2f}",
                 f"{fem_a.time_s:.2f} ({emu.vertex_error(fem_a, ref):.1e})"]
        for resolve, corrected in runs:
            cells.append(f"{resolve.time_s:.2f} "
                         f"({resolve.settings['alpha_attempts']}, {emu.vertex_error(resolve, ref):.1e})")
            cells.append(f"{corrected.time_s:.2f} "
                         f"({corrected.settings['alpha_attempts']}, {'yes' if corrected.corrected else 'no'}, "
                         f"{corrected.error_estimate:.1e}, {emu.vertex_error(corrected, ref):.1e})")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
