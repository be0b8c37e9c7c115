"""Stiff and extreme cases on both solvers: what emu does, in how many
iterations, to what residual, with how many inverted tets, in what time.
The cases are shared with the stress tests (tests/stress), which assert the
physical checks on each; this script prints the table of docs/stability.md.

    python bench/stability.py [--only tendon_ratio poisson ...] [--threads 1]

Scene kinds (all small): the procedural fusiform muscle (432 tets) pinned at
its proximal end; the arm (228 tets) with the forearm fixed or on its hinge;
the neck (738 tets: a head on a ball joint); a chain of two movable bones (48
tets, EMU only); a pinned bar (192 tets) for mesh defects. Each case pushes
one thing; EMU at its accuracy default unless the case sets alpha or k.
"""
from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

import emu
from bench_scenes import start_run
from emu.core.checks import signed_volumes
from emu.build.procedural import block_mesh
from emu.build.procedural import fusiform as fusiform_mesh

MUSCLE_YOUNGS = 6e4
FRAMES = 50


def pinned_muscle(*, tendon_ratio=7500.0, poisson=0.49, scale=1.0, resolution=2):
    """The pinned fusiform with a tendon tendon_ratio times stiffer than the belly."""
    m = fusiform_mesh(resolution)
    s = emu.Scene(m.points * scale, m.tets, warn=False)
    s.add_muscle("belly", ~m.is_tendon, m.fibers[~m.is_tendon], youngs=MUSCLE_YOUNGS, poisson=poisson)
    s.add_tendon("tendons", m.is_tendon, youngs=tendon_ratio * MUSCLE_YOUNGS, poisson=poisson)
    s.pin(m.proximal)
    return s


def arm(*, forearm_fixed=False, bone_ratio=None, bone_acap_weight=None, joint_stiffness=0.0):
    """The arm at resolution 1; bone_ratio: the bones' Young's modulus over the
    muscles' (they are rigid: it must not matter); bone_acap_weight: EMU's."""
    m = emu.procedural.arm(1)
    s = emu.Scene(m.points, m.tets, warn=False)
    bone = {}
    if bone_ratio is not None:
        bone["youngs"] = bone_ratio * MUSCLE_YOUNGS
    if bone_acap_weight is not None:
        bone["acap_weight"] = bone_acap_weight
    s.add_bone("humerus", m.parts["humerus"], **bone)
    s.add_bone("forearm", m.parts["forearm"], fixed=forearm_fixed, joint_stiffness=joint_stiffness, **bone)
    for name in ("flexor", "extensor"):
        s.add_muscle(name, m.parts[name], youngs=MUSCLE_YOUNGS)
    s.resolve_fibers()
    return s


def bar(blocks=4, resolution=2, offset=(0, 0)):
    """(points, tets) of a bar of unit blocks along z."""
    return block_mesh({"m": [(offset[0], offset[1], k) for k in range(blocks)]}, resolution)[:2]


def pinned_bar(points, tets, *, fibers=(0.0, 0.0, 1.0)):
    """A muscle on the mesh, pinned where z = 0."""
    s = emu.Scene(points, tets, warn=False)
    s.add_muscle("belly", np.arange(len(s.tets)), None if fibers is None else np.asarray(fibers, float),
                 youngs=MUSCLE_YOUNGS)
    s.pin(np.flatnonzero(s.points[:, 2] < 1e-9))
    return s


def sliver_bar(volume_ratio):
    """The pinned bar with an interior vertex moved toward the opposite face of
    one of its tets until that tet (and the one coplanar with it) keeps only
    volume_ratio of its volume: slivers (1e-3) and near-zero-volume tets (1e-8)."""
    points, tets = bar()
    vol = signed_volumes(points, tets)
    lo, hi = points.min(0), points.max(0)
    interior = np.flatnonzero(np.all((points > lo + 1e-9) & (points < hi - 1e-9), axis=1))
    best = None
    for v in interior[:8]:
        incident = np.flatnonzero(np.any(tets == v, axis=1))
        for t in incident:
            a, b, c = points[[w for w in tets[t] if w != v]]
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            p = points.copy()
            p[v] -= (1.0 - volume_ratio) * ((points[v] - a) @ n) * n
            worst = np.min(signed_volumes(p, tets[incident]) / vol[incident])
            if worst > 0.5 * volume_ratio and (best is None or worst > best[0]):
                best = (worst, p)
    return pinned_bar(best[1], tets)


def every_other_flipped(tets):
    """tets (m, 4) with every other tet's vertex order reversed (negative volume)."""
    tets = tets.copy()
    tets[::2] = tets[::2][:, [0, 2, 1, 3]]
    return tets


def inverted_bar():
    """The pinned bar with every other tet given with negative rest volume: emu
    reorients them (with a MeshWarning) and must solve as if it were given the
    oriented mesh."""
    points, tets = bar()
    return pinned_bar(points, every_other_flipped(tets))


def single_tet():
    """One tet, a muscle with its fibre along z, the base face pinned."""
    s = emu.Scene(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]), warn=False)
    s.add_muscle("belly", [0], [0.0, 0.0, 1.0], youngs=MUSCLE_YOUNGS)
    s.pin([0, 1, 2])
    return s


def two_bars(*, second_pinned=True):
    """Two bars that share no vertex (disconnected parts), each a muscle; the
    first pinned at z = 0, the second too unless second_pinned=False."""
    p1, t1 = bar(blocks=3)
    p2, t2 = bar(blocks=3, offset=(3, 0))
    points, tets = np.vstack([p1, p2]), np.vstack([t1, t2 + len(p1)])
    s = emu.Scene(points, tets, warn=False)
    s.add_muscle("belly", np.arange(len(t1)), [0.0, 0.0, 1.0], youngs=MUSCLE_YOUNGS)
    s.add_muscle("second", np.arange(len(t1), len(tets)), [0.0, 0.0, 1.0], youngs=MUSCLE_YOUNGS)
    base = s.points[:, 2] < 1e-9
    s.pin(np.flatnonzero(base if second_pinned else base & (np.arange(len(points)) < len(p1))))
    return s


def jumps(muscles, low, high, frames=FRAMES):
    """frame -> {muscle: activation}: every muscle jumps between low and high
    without ramps, in a pattern that changes which muscles fire every 3 frames."""
    def activation(k):
        on = (k // 3) % (len(muscles) + 1)
        return {m: (high if (i + 1 == on or (on == 0 and k % 2)) else low) for i, m in enumerate(muscles)}
    return activation


@dataclass(frozen=True)
class Case:
    """One stress case.

    scene       () -> emu.Scene
    activation  {muscle: absolute activation}, or frame -> that dict (a sequence)
    frames      solves, each warm-started from the last
    emu         EMU-only solver options (alpha, modes, ...): FEM skips the case
    refuses     {method: regex}: that method must refuse the scene with a
                ValueError whose message matches (all: "*")
    """
    label: str
    scene: Callable
    activation: object
    frames: int = 1
    emu: dict = field(default_factory=dict)
    refuses: dict = field(default_factory=dict)

    def methods(self):
        return ("emu",) if self.emu else ("fem", "emu")

    def refusal(self, method):
        return self.refuses.get(method, self.refuses.get("*"))

    def activation_at(self, k):
        return self.activation(k) if callable(self.activation) else self.activation


NO_FIBRES = "no fibres and 0 bone attachment"
CASES = {
    "tendon_ratio": [Case(f"tendon / muscle {r:g}", lambda r=r: pinned_muscle(tendon_ratio=r), {"belly": 5e4})
                     for r in (1, 1e3, 1e5, 1e7)],
    "poisson": [Case(f"Poisson {nu:g}", lambda nu=nu: pinned_muscle(poisson=nu), {"belly": 5e4})
                for nu in (0.45, 0.49, 0.499, 0.4999)],
    "activation": [Case(f"activation {a:g}", pinned_muscle, {"belly": a})
                   for a in (0.0, 1e4, 1e5, 1e6, 1e8, 1e9, 1e10, 1e12)],
    "scale": [Case(f"coordinates x {c:g}", lambda c=c: pinned_muscle(scale=c), {"belly": 5e4}) for c in (1e-4, 1e4)],
    "alpha": [Case(f"alpha {a:g} mu", pinned_muscle, {"belly": 5e4}, emu=dict(alpha=a)) for a in (1e-2, 1e2, 1e8)],
    "modes": [Case(f"k = {k}", pinned_muscle, {"belly": 5e4}, emu=dict(modes=k, alpha=100.0)) for k in (0, 96, 300)],
    "bones": [
        Case("fixed bones (arm, forearm fixed), flexor 1e6", lambda: arm(forearm_fixed=True), {"flexor": 1e6}),
        Case("hinge (arm), flexor 1e5", arm, {"flexor": 1e5}),
        Case("hinge (arm), flexor 1e8", arm, {"flexor": 1e8}),
        Case("ball joint (neck), left_front 1e5", lambda: emu.scenes.neck(1), {"left_front": 1e5}),
        Case("ball joint (neck), left_front 1e8", lambda: emu.scenes.neck(1), {"left_front": 1e8}),
        Case("chain (two movable bones), m1 + m2 2e4", lambda: emu.scenes.chain(1), {"m1": 2e4, "m2": 2e4}),
        Case("chain (two movable bones), m1 + m2 1e6", lambda: emu.scenes.chain(1), {"m1": 1e6, "m2": 1e6}),
    ],
    "bone_stiffness": [Case(f"hinge, bone / muscle {r:g}", lambda r=r: arm(bone_ratio=r), {"flexor": 1e6})
                       for r in (1e3, 1e8)]
    + [Case(f"hinge, bone ACAP weight {w:g}", lambda w=w: arm(bone_acap_weight=w), {"flexor": 1e6},
             emu=dict(accuracy=0.01)) for w in (1e2, 1e8)]
    + [Case(f"hinge, joint stiffness {k:g}", lambda k=k: arm(joint_stiffness=k), {"flexor": 1e6})
       for k in (1e-2, 1e3)],
    "sequence": [
        Case(f"pinned muscle, {FRAMES} frames, jumps 0 <-> 1e6", pinned_muscle, jumps(["belly"], 0.0, 1e6),
              frames=FRAMES),
        Case(f"hinge (arm), {FRAMES} frames, jumps 0 <-> 1e6", arm, jumps(["flexor", "extensor"], 0.0, 1e6),
              frames=FRAMES),
        Case(f"ball joint (neck), {FRAMES} frames, jumps 0 <-> 1e6", lambda: emu.scenes.neck(1),
              jumps(list(emu.procedural.NECK_MUSCLES), 0.0, 1e6), frames=FRAMES),
    ],
    "mesh": [
        Case("two sliver tets (volume x 1e-3)", lambda: sliver_bar(1e-3), {"belly": 1e5}),
        Case("two near-zero-volume tets (x 1e-8)", lambda: sliver_bar(1e-8), {"belly": 1e5}),
        Case("half the rest tets inverted", inverted_bar, {"belly": 1e5}),
        Case("a single-tet muscle", single_tet, {"belly": 1e5}),
        Case("disconnected parts, both pinned", two_bars, {"belly": 1e5, "second": 5e4}),
        Case("disconnected parts, one unpinned", lambda: two_bars(second_pinned=False), {"belly": 1e5},
              refuses={"*": "no pinned vertex"}),
        Case("a muscle without fibres", lambda: pinned_bar(*bar(), fibers=None), {"belly": 1e5},
              refuses={"*": NO_FIBRES}),
    ],
}


@dataclass
class Outcome:
    """What one method did on one case: its scene and per-frame solutions, or the
    message it refused the scene with."""
    scene: emu.Scene | None
    solutions: list
    seconds: float
    refused: str = ""


def run_case(method, case: Case, max_iterations=300) -> Outcome:
    """Build the case's scene and solve every frame (warm-started), or catch the
    ValueError the case expects this method to refuse it with."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            scene = case.scene()
            solver = emu.Solver(scene, method, max_iterations=max_iterations,
                                **(case.emu if method == "emu" else {}))
        except ValueError as e:
            if case.refusal(method) is None:
                raise
            return Outcome(None, [], time.perf_counter() - t0, refused=str(e))
        solutions = list(emu.solve_frames(solver, (case.activation_at(k) for k in range(case.frames))))
    return Outcome(scene, solutions, time.perf_counter() - t0)


def row(case: Case, method, out: Outcome):
    if out.refused:
        return f"| {case.label} | {method} | refused: {out.refused.split(';')[0]} | - | - | - | - | {out.seconds:.2f} |"
    sols = out.solutions
    done = sum(s.converged for s in sols)
    corrected = sum(s.corrected for s in sols)
    if len(sols) == 1:
        state = ("converged" if done else sols[0].status.split(":")[0]) + (", FEM-corrected" if corrected else "")
    else:
        state = f"{done} / {len(sols)} frames converged" + (f", {corrected} FEM-corrected" if corrected else "")
    its = sum(s.iterations for s in sols)
    cg = sum(s.cg_iterations for s in sols)
    # a sequence: the largest final |g| of a frame over the largest |g0| of any (a frame warm-started
    # at its equilibrium has a tiny |g0| of its own, and its ratio says nothing)
    g0 = max(s.grad_norm0 for s in sols)
    rel = max(s.grad_norm for s in sols) / g0 if g0 else 0.0
    est = [s.error_estimate for s in sols if s.error_estimate is not None]
    est = f"{max(est):.1e}" if est else "-"
    inverted = max(s.inverted_tets for s in sols)
    return (f"| {case.label} | {method} | {state} | {its}{f' / {cg}' if cg else ''} | {rel:.1e} | {inverted} | "
            f"{est} | {out.seconds:.2f} |")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    print("| case | method | result | iterations (/ CG) | final |g| / |g0| | inverted tets | EMU's error estimate | s |")
    print("|---|---|---|---|---|---|---|---|")
    for group in a.only:
        for case in CASES[group]:
            for method in case.methods():
                print(row(case, method, run_case(method, case)), flush=True)


if __name__ == "__main__":
    main()
