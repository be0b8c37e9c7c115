"""A scene file's frames solved by EMU as shipped, by FEM at the same accuracy
and by strict FEM: per frame, EMU's own answer's error to strict FEM against
what one FEM Newton step from it reads (the estimate before its certificate)
and what the estimate reads (the certificate's last step), the certificate's
contractions (each step over the one before), whether the estimate certified
itself, whether the answer was corrected or settled by FEM, and the answer's final error; then
both methods' totals.

    python bench/studies/frame_estimates.py SCENE.toml [--frames N] [--threads 1]

docs/DESIGN.md, "The estimate's certificate", quotes it on the arm26 elbow
(../shared/data/arm26: `emu mesh parts.toml --out mesh`, flex.toml beside
mesh.vtu).
"""
from __future__ import annotations

import argparse
import time
import warnings

import emu
from emu.app.scenefile import load_scene_file


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("--frames", type=int, default=None, help="the first N frames (default: all)")
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args(argv)
    if a.threads:
        emu.runtime.set_threads(a.threads)
    warnings.simplefilter("ignore")
    spec = load_scene_file(a.scene)
    i = emu.info()
    print(f"emu {i['version']}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; {time.strftime('%Y-%m-%d')}")
    print()
    ours = emu.Solver(spec.scene, **{**spec.solver, "method": "emu"})
    fem = emu.Solver(spec.scene, "fem", accuracy=ours.accuracy or 0.01)
    strict = emu.Solver(spec.scene, "fem", rtol_grad=1e-9)
    print("| frame | EMU's own error | one step reads | estimate reads | contractions | certified | answer | "
          "final error | EMU s | FEM s | FEM error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    total = {"emu": 0.0, "fem": 0.0}
    frames = spec.frames if a.frames is None else min(a.frames, spec.frames)
    loads = spec.frame_loads(range(frames))
    runs = {name: emu.solve_frames(s, loads) for name, s in (("emu", ours), ("fem", fem), ("strict", strict))}
    for k in range(frames):
        sols = {name: next(run) for name, run in runs.items()}
        e, ref = sols["emu"], sols["strict"].positions
        total["emu"] += e.time_s
        total["fem"] += sols["fem"].time_s
        own = e.emu_positions if e.emu_positions is not None else e.positions
        one = two = contraction = "-"
        if e.fem_correction is not None:
            d1 = emu.vertex_error(own, e.fem_correction)
            one = f"{d1:.2e}"
            if e.fem_check is not None:
                two = f"{emu.vertex_error(own, e.fem_check):.2e}"
                chain = e.fem_steps
                steps = [d1] + [emu.vertex_error(a, b) for a, b in zip(chain, chain[1:])]
                contraction = ", ".join(f"{b / a:.2f}" if a > 0 else "0" for a, b in zip(steps, steps[1:]))
        cert = {None: "-", True: "yes", False: "no"}[e.error_estimate_certified]
        answer = ("settled" if e.error_estimate_certified is False else "corrected") if e.corrected else "EMU's"
        print(f"| {k} | {emu.vertex_error(own, ref):.2e} | {one} | {two} | {contraction} | {cert} | {answer} | "
              f"{emu.vertex_error(e, ref):.2e} | {e.time_s:.2f} | {sols['fem'].time_s:.2f} | "
              f"{emu.vertex_error(sols['fem'], ref):.2e} |", flush=True)
    print(f"\nEMU {total['emu']:.2f} s, FEM at the same accuracy {total['fem']:.2f} s "
          f"(FEM / EMU {total['fem'] / total['emu']:.2f}x)")


if __name__ == "__main__":
    main()
