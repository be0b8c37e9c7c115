"""Stiff and extreme cases on both solvers: what emu does, in how many
iterations, to what residual, with how many inverted tets, in what time.
The cases are shared with the stress tests (tests/stress), which assert the
physical checks on each; this script prints the table of docs/stability.md.

    python bench/stability.py [--only tendon_ratio poisson ...] [--threads 1]

Each case: the procedural fusiform muscle (resolution 2: 432 tets) pinned at
its proximal end, the belly activated, one parameter pushed; EMU at its
accuracy default unless the case sets alpha or k.
"""
from __future__ import annotations

import argparse
import time
import warnings


import emu
from bench_scenes import start_run
from emu.meshes import fusiform as fusiform_mesh

MUSCLE_YOUNGS = 6e4


def pinned_muscle(*, tendon_ratio=7500.0, poisson=0.49, scale=1.0, resolution=2):
    """The pinned fusiform with a tendon tendon_ratio times stiffer than the belly."""
    m = fusiform_mesh(resolution)
    s = emu.Scene(m.points * scale, m.tets, warn=False)
    s.add_muscle("belly", ~m.is_tendon, m.fibers[~m.is_tendon], youngs=MUSCLE_YOUNGS, poisson=poisson)
    s.add_tendon("tendons", m.is_tendon, youngs=tendon_ratio * MUSCLE_YOUNGS, poisson=poisson)
    s.pin(m.proximal)
    return s


# name -> list of (label, scene builder kwargs, activation of the belly, EMU-only solver kwargs or None)
CASES = {
    "tendon_ratio": [(f"tendon / muscle {r:g}", dict(tendon_ratio=r), 5e4, {}) for r in (1, 1e3, 1e5, 1e7)],
    "poisson": [(f"Poisson {nu:g}", dict(poisson=nu), 5e4, {}) for nu in (0.45, 0.49, 0.499, 0.4999)],
    "activation": [(f"activation {a:g}", {}, a, {}) for a in (0.0, 1e4, 1e5, 1e6, 1e8)],
    "scale": [(f"coordinates x {c:g}", dict(scale=c), 5e4, {}) for c in (1e-4, 1e4)],
    "alpha": [(f"alpha {a:g} mu", {}, 5e4, dict(alpha=a)) for a in (1e-2, 1e2, 1e8)],
    "modes": [(f"k = {k}", {}, 5e4, dict(modes=k, alpha=100.0)) for k in (0, 96)],
}


def run_case(method, scene_kw, activation, emu_kw, max_iterations=300):
    """(Solution, seconds) of one case, or None where the case is EMU's only."""
    if method == "fem" and emu_kw:
        return None
    scene = pinned_muscle(**scene_kw)
    kw = dict(max_iterations=max_iterations)
    if method == "emu":
        kw.update(emu_kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        sol = emu.Solver(scene, method, **kw).solve({"belly": activation})
    return scene, sol, time.perf_counter() - t0


def row(label, method, scene, sol, seconds):
    rel = sol.grad_norm / sol.grad_norm0 if sol.grad_norm0 else 0.0
    state = "converged" if sol.converged else sol.status.split(":")[0]
    cg = f" / {sol.cg_iterations}" if sol.cg_iterations else ""
    est = f"{sol.error_estimate:.1e}" if sol.error_estimate is not None else "-"
    return (f"| {label} | {method} | {state} | {sol.iterations}{cg} | {rel:.1e} | {sol.inverted_tets} | {est} | "
            f"{seconds:.2f} |")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=list(CASES))
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    print("| case | method | result | iterations (/ CG) | final |g| / |g0| | inverted tets | EMU's error estimate | s |")
    print("|---|---|---|---|---|---|---|---|")
    for group in a.only:
        for label, scene_kw, activation, emu_kw in CASES[group]:
            for method in ("fem", "emu"):
                out = run_case(method, scene_kw, activation, emu_kw)
                if out is not None:
                    print(row(label, method, *out), flush=True)


if __name__ == "__main__":
    main()
