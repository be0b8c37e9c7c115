"""Every example scene file with its own settings (EMU's default accuracy 0.01):
EMU's largest vertex error to FEM over all frames, its own estimate, times,
and the FEM factorisations its error estimates made.

    python bench/examples_error.py [examples/*.toml] [--emu-step-fraction F]

--emu-step-fraction F: EMU's accuracy stopping rule at F of the target
instead of the scene's (Solver(step_fraction=F)).
"""
from __future__ import annotations

import glob
import os
import sys
import time
import warnings

import emu
from emu.app.scenefile import load_scene_file

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    args = list(argv if argv is not None else sys.argv[1:])
    extra = {}
    if "--emu-step-fraction" in args:
        i = args.index("--emu-step-fraction")
        extra["step_fraction"] = float(args[i + 1])
        del args[i:i + 2]
    paths = args or sorted(glob.glob(os.path.join(HERE, "..", "examples", "*.toml")))
    warnings.simplefilter("ignore")
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}\n")
    print("| example | tets | frames | EMU settings | EMU s (of it estimates s) | FEM s | max true error | max estimate | "
          "alpha range | estimate's factorisations |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        spec = load_scene_file(path)
        emu_solver = emu.Solver(spec.scene, **{**spec.solver, "method": "emu", **extra})
        fem_solver = emu.Solver(spec.scene, "fem", rtol_grad=1e-9)
        prev_e = prev_f = None
        worst = worst_est = 0.0
        te = tf = test = 0.0
        alphas = []
        for k in range(spec.frames):
            act, poses = spec.activation(k), spec.bone_poses(k) or None
            se = emu_solver.solve(act, bone_poses=poses, initial=prev_e)
            sf = fem_solver.solve(act, bone_poses=poses, initial=prev_f)
            prev_e, prev_f = se, sf
            te, tf, test = te + se.time_s, tf + sf.time_s, test + se.error_estimate_time_s
            worst = max(worst, emu.vertex_error(se, sf))
            worst_est = max(worst_est, se.error_estimate or 0.0)
            alphas.append(se.settings["alpha"])
        mode = f"accuracy {emu_solver.accuracy:g}" if emu_solver.accuracy else f"alpha {emu_solver.alpha:g}"
        print(f"| {os.path.basename(path)} | {len(spec.scene.tets)} | {spec.frames} | {mode} | {te:.2f} ({test:.2f}) | "
              f"{tf:.2f} | {worst:.2e} | {worst_est:.2e} | {min(alphas):.0f}-{max(alphas):.0f} | "
              f"{getattr(emu_solver._estimator, 'factorizations', 0)} |", flush=True)


if __name__ == "__main__":
    main()
