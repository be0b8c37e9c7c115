"""Contact: what it changes and what it costs.

The elbow_wrap scene (emu.scenes.elbow_wrap: the flexor bends the elbow far
and stretches the extensor across the elbow's corner), its flexor ramped 0 ->
1 over a sequence of frames, solved by FEM and by EMU (accuracy 0.01), each
with contact on and off. Printed per case: the frames' total solve time,
Newton iterations (and CG), the time in contact (ipctk: the active pairs, the
barrier's energy, gradient and Hessian, continuous collision detection) and
its share, per Newton iteration, and whether the extensor passes through a
bone in any frame; EMU's vertex error with contact on, to FEM's answer of the
same frame and to the FEM equilibrium nearest EMU's (FEM warm-started from
it: frictionless sliding leaves a nearly flat valley), and EMU's own error
estimate; then the same with accuracy mode's FEM correction forced on
(fem_correction=True; off by default with contact). A PNG compares the
frames with contact off and on.

    python bench/studies/contact.py [--resolution 2] [--frames 12] [--threads 1] [--out bench/studies/contact]
    python bench/studies/contact.py --steps     # EMU's steps with contact on beam_on_bone, against FEM
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

import emu
import sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import start_run
from emu.model.contact import ContactSettings, ContactTerm
from emu.io.plots import contact_sheet

MAX_ACTIVATION = 2e6


def run(resolution: int, frames: int, method: str, contact: bool, fem_correction=None) -> dict:
    scene = emu.scenes.elbow_wrap(resolution, max_activation=MAX_ACTIVATION)
    bones = ContactTerm(scene, ContactSettings(pairs=[("extensor", "humerus"), ("extensor", "forearm")]))
    if contact:
        scene.enable_contact()
    solver = emu.Solver(scene, method, **({"accuracy": 0.01, "fem_correction": fem_correction}
                                          if method == "emu" else {}))
    prev, out = None, {"positions": [], "estimates": [], "activations": [], "corrected": 0, "solve_s": 0.0, "estimate_s": 0.0, "iterations": 0, "cg": 0,
                       "through": 0, "converged": True}
    t0 = time.perf_counter()
    for a in np.linspace(0.0, 1.0, frames):
        sol = solver.solve({"flexor": float(a)}, normalized=True, initial=prev)
        prev = sol
        out["solve_s"] += sol.solve_time_s
        out["estimate_s"] += sol.error_estimate_time_s
        out["iterations"] += sol.iterations
        out["cg"] += sol.cg_iterations
        out["converged"] &= sol.converged
        out["through"] += bones.intersecting(sol.positions)
        out["positions"].append(sol.positions)
        out["estimates"].append(sol.error_estimate)
        out["corrected"] += sol.corrected
        out["activations"].append(float(a))
    out["wall_s"] = time.perf_counter() - t0
    out["contact_s"] = sum(solver.contact.seconds.values()) if solver.contact else 0.0
    out["contact_parts"] = dict(solver.contact.seconds) if solver.contact else {}
    out["angle"] = emu.bones.bone_angle(scene, prev.positions, "forearm")
    out["scene"] = scene
    out["tets"] = len(scene.tets)
    return out


def steps():
    """Each EMU step (and the Schur preconditioner) on beam_on_bone with contact
    (gravity pressing the beam onto the bone, alpha = 100 mu), against FEM."""
    scene = emu.scenes.beam_on_bone()
    scene.enable_contact()
    g = np.array([0.0, 0.0, -100.0])
    ref = emu.solve(scene, method="fem", gravity=g)
    print("| EMU step | converged | status | iterations (CG) | s | error to FEM | intersecting |")
    print("|---|---|---|---|---|---|---|")
    for label, kw in (("newton-krylov", {}), ("newton-krylov, schur", {"preconditioner": "schur"}),
                      ("lbfgs", {"step": "lbfgs"}), ("woodbury", {"step": "woodbury", "max_iterations": 300})):
        sol = emu.Solver(scene, "emu", alpha=100.0, error_estimate=False, **kw).solve(gravity=g)
        print(f"| {label} | {sol.converged} | {sol.status.split(':')[0]} | {sol.iterations} ({sol.cg_iterations}) | "
              f"{sol.time_s:.2f} | {emu.vertex_error(sol.positions, ref.positions, scene.points):.2e} | "
              f"{sol.contact['intersecting']} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "contact"))
    ap.add_argument("--steps", action="store_true", help="only the table of EMU's steps with contact")
    args = ap.parse_args()
    start_run(args.threads)
    if args.steps:
        steps()
        return
    os.makedirs(args.out, exist_ok=True)
    print("| tets | method | contact | solve s (+ estimate) | Newton (CG) | contact s | share | contact ms / "
          "Newton | frames through a bone | elbow deg |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for res in args.resolution:
        runs = {}
        for method in ("fem", "emu"):
            for contact in (False, True):
                r = run(res, args.frames, method, contact)
                runs[method, contact] = r
                cg = f" ({r['cg']})" if r["cg"] else ""
                est = f" (+ {r['estimate_s']:.2f})" if method == "emu" else ""
                share = r["contact_s"] / max(r["solve_s"] + r["estimate_s"], 1e-12)
                per = 1e3 * r["contact_s"] / max(r["iterations"], 1)
                print(f"| {r['tets']} | {method} | {'on' if contact else 'off'} | {r['solve_s']:.2f}{est} | "
                      f"{r['iterations']}{cg} | {r['contact_s']:.2f} | {100 * share:.0f}% | {per:.1f} | "
                      f"{r['through']} of {args.frames} | {r['angle']:.1f} |"
                      + ("" if r["converged"] else " not converged"))
        f = runs["fem", True]
        pts = f["scene"].points
        nearest = emu.Solver(f["scene"], "fem")
        for label, e in (("default (no FEM correction)", runs["emu", True]),
                         ("fem_correction=True", run(res, args.frames, "emu", True, fem_correction=True))):
            err = [emu.vertex_error(a, b, pts) for a, b in zip(e["positions"], f["positions"])]
            near = [emu.vertex_error(x, nearest.solve({"flexor": a}, normalized=True, initial=x).positions, pts)
                    for x, a in zip(e["positions"], e["activations"])]
            ratios = [est / t for est, t in zip(e["estimates"], near) if est is not None and t > 1e-6]
            print(f"\n{f['tets']} tets, EMU with contact, {label}: {e['corrected']} of {args.frames} frames "
                  f"FEM-corrected; vertex error over the frames {min(err):.2e} to {max(err):.2e} of the diagonal to "
                  f"FEM's sequence, {min(near):.2e} to {max(near):.2e} to the FEM equilibrium nearest it; its "
                  f"estimate / that error {min(ratios):.2f} to {max(ratios):.2f}")
        parts = runs["emu", True]["contact_parts"]
        print("EMU's contact time by call: " + ", ".join(f"{k} {v:.2f} s" for k, v in parts.items()) + "\n")
        scene = runs["emu", True]["scene"]
        picks = [0, args.frames // 2, args.frames - 1]
        frames = [runs["emu", False]["positions"][i] for i in picks] + [runs["emu", True]["positions"][i] for i in picks]
        titles = [f"contact off, flexor {i / (args.frames - 1):.2f}" for i in picks] + \
                 [f"contact on, flexor {i / (args.frames - 1):.2f}" for i in picks]
        path = os.path.join(args.out, f"elbow_wrap_r{res}.png")
        contact_sheet(path, scene, frames, titles=titles,
                      activations=[{"flexor": i / (args.frames - 1), "extensor": 0.0} for i in picks] * 2, columns=3)
        print(f"wrote {path}\n")


if __name__ == "__main__":
    main()
