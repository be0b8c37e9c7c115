"""EMU's Newton on a chain of movable bones (the built-in upper limb, no
shoulder spring): how the bone coordinates, step kinds and Hessians behave,
against strict FEM.
Per variant: Newton iterations, CG iterations, converged, seconds, the error
to FEM, and the first step lengths (the line search's cuts).

    python bench/studies/chain_convergence.py [--muscle biceps] [--activation 0.3] [--alpha 100]
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import emu

VARIANTS = {
    "default (joint coordinates)": {},
    "per bone": {"joint_coordinates": False},
    "filtered Hessian only": {"exact_when_definite": False},
    "no bone coarse space": {"bone_coarse_space": False},
    "L-BFGS": {"step": "lbfgs"},
}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--muscle", default="biceps")
    ap.add_argument("--activation", type=float, default=0.3)
    ap.add_argument("--alpha", type=float, default=100.0)
    ap.add_argument("--max-iterations", type=int, default=500)
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    s = emu.anatomy.upper_limb(1)
    for name in s.movable_bones:
        s.parts[name].joint_stiffness = 0.0
    act = {a.muscle: a.activation}
    fem = emu.solve(s, act, "fem", normalized=True, rtol_grad=1e-10)
    print(f"upper_limb(1), no spring, {a.muscle} {a.activation}: FEM {fem.iterations} iterations, "
          f"converged {fem.converged}\n")
    print("| variant | Newton | CG | converged | s | error to FEM | first steps |")
    print("|---|---|---|---|---|---|---|")
    for label, kw in VARIANTS.items():
        t0 = time.perf_counter()
        sol = emu.solve(s, act, "emu", normalized=True, alpha=a.alpha, max_iterations=a.max_iterations, **kw)
        steps = np.round(sol.history["step"][1:13], 2).tolist()
        print(f"| {label} | {sol.iterations} | {sol.cg_iterations} | {sol.converged} | "
              f"{time.perf_counter() - t0:.2f} | {emu.vertex_error(sol, fem):.2e} | {steps} |")


if __name__ == "__main__":
    main()
