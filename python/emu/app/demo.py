"""``emu demo``: the built-in arm, flexing then extending the elbow.

The built-in arm from smooth shapes (emu.anatomy.arm, meshed on first use and
cached): the humerus fixed, the forearm on a hinge moved by a flexor, which
fires first, then an extensor. Each frame is
solved by EMU (warm-started from the last) and, for an honest comparison, by
FEM; the outputs are those of ``emu run`` plus a PNG contact sheet and a plot
of joint angle and activation over time, and summary.json with EMU's error
against FEM.
"""
from __future__ import annotations

import json
import os

import numpy as np

from ..core.activation import Curve
from ..model.bones import bone_angle
from ..core.geometry import vertex_error
from ..io.plots import angle_activation_plot, contact_sheet
from ..build.anatomy import arm
from ..solve.solver import Solver
from ..solve.frames import solve_frames
from .run import run_scene
from .scenefile import SceneSpec

__all__ = ["demo_spec", "run_demo"]


def demo_spec(resolution: int = 3, frames: int = 25, alpha: float | None = None, accuracy: float | None = None,
              progress=None):
    """The demo scene as a SceneSpec: 2 s, flexor up to 0.45 and back in the
    first second, extensor up to 1.0 and back in the second. EMU's default:
    accuracy 0.01 (alpha chosen for it) unless alpha is given."""
    scene = arm(resolution, progress=progress)
    dt = 2.0 / (frames - 1)
    curves = {"flexor": Curve(keys=[[0.0, 0.0], [0.5, 0.45], [1.0, 0.0]], interpolation="smooth"),
              "extensor": Curve(keys=[[0.0, 0.0], [1.0, 0.0], [1.5, 1.0], [2.0, 0.0]], interpolation="smooth")}
    solver = {"method": "emu"}
    if alpha is not None:
        solver["alpha"] = alpha
    if accuracy is not None:
        solver["accuracy"] = accuracy
    return SceneSpec(scene=scene, solver=solver, frames=frames, dt=dt,
                     curves=curves, source="built-in arm (emu.anatomy.arm)")


def run_demo(out: str, resolution: int = 3, frames: int = 25, alpha: float | None = None, compare_fem: bool = True,
             progress=print, accuracy: float | None = None) -> dict:
    """Run the demo into ``out`` (see the module docstring); returns summary.json's contents."""
    spec = demo_spec(resolution, frames, alpha, accuracy, progress=lambda m: progress(f"emu demo: {m}"))
    scene = spec.scene
    os.makedirs(out, exist_ok=True)
    progress(f"emu demo: the built-in arm, {len(scene.tets)} tets, {len(scene.points)} vertices; humerus fixed, "
             "forearm on a hinge; the flexor fires, then the extensor")
    kept = {}
    log = run_scene(spec, out, progress=progress, on_frame=lambda k, sol: kept.__setitem__(k, sol.positions))
    done = sorted(kept)
    times = np.array([k * spec.dt for k in done])
    angle = np.array([log["frames"][k]["bone_angles_deg"]["forearm"] for k in done])
    acts = {m: np.array([spec.curves[m].value(k, k * spec.dt) for k in done]) for m in spec.curves}
    alphas = [f["alpha"] for f in log["frames"]]
    mode = (f"alpha = {alpha:g} mu" if alpha is not None and accuracy is None else
            f"accuracy {log['settings'].get('accuracy'):g}, alpha {min(alphas):.0f}-{max(alphas):.0f} mu")
    summary = {"tets": len(scene.tets), "vertices": len(scene.points), "frames": len(done), "alpha": alphas,
               "accuracy": log["settings"].get("accuracy"),
               "emu_time_s": float(sum(f["time_s"] for f in log["frames"])),
               "emu_solve_s": float(sum(f["solve_s"] for f in log["frames"])),
               "emu_error_estimate_s": float(sum(f.get("error_estimate_s", 0.0) for f in log["frames"])),
               "emu_iterations": [f["iterations"] for f in log["frames"]],
               "emu_cg_iterations": [f["cg_iterations"] for f in log["frames"]],
               "all_converged": all(f["converged"] for f in log["frames"]),
               "emu_error_estimate": [f["error_estimate"] for f in log["frames"]],
               "fem_corrected": [bool(f.get("fem_corrected")) for f in log["frames"]],
               "elbow_angle_deg": angle.tolist(), "time_s": times.tolist()}
    reference = None
    if compare_fem and done:
        reference = {"FEM": _fem_reference(spec, kept, done, angle, summary, mode, progress)}
    picks = sorted(set(np.linspace(0, len(done) - 1, min(8, len(done))).round().astype(int).tolist()))
    sheet = os.path.join(out, "contact_sheet.png")
    contact_sheet(sheet, scene, [kept[done[i]] for i in picks],
                  titles=[f"t = {times[i]:.2f} s, elbow {angle[i]:+.1f} deg" for i in picks],
                  activations=[{m: acts[m][i] for m in acts} for i in picks])
    plot = os.path.join(out, "elbow_angle.png")
    angle_activation_plot(plot, times, {"EMU": angle}, acts, reference=reference,
                          title=f"arm demo: elbow angle (flexion > 0) and activation, {mode}")
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    progress(f"wrote {out}/: frame_*.vtu + series.pvd (ParaView), frame_*.obj (Blender), log.json, "
             f"contact_sheet.png, elbow_angle.png, summary.json")
    return summary


def _fem_reference(spec, kept: dict, done: list, angle, summary: dict, mode: str, progress):
    """FEM's answers at the demo's frames (warm-started), EMU's errors to them and
    its estimate's ratio to them into ``summary``; returns FEM's elbow angles."""
    scene = spec.scene
    progress("FEM reference for every frame (for EMU's error):")
    fem = Solver(scene, "fem")
    fem_angle, errors, fem_s = [], [], 0.0
    for k, sol in zip(done, solve_frames(fem, spec.frame_loads(done))):
        fem_s += sol.time_s
        fem_angle.append(bone_angle(scene, sol.positions, "forearm"))
        errors.append(vertex_error(kept[k], sol))
    fem_angle = np.array(fem_angle)
    summary.update(fem_time_s=fem_s, fem_solve_s=fem_s, fem_elbow_angle_deg=fem_angle.tolist(),
                   max_angle_difference_deg=float(np.abs(angle - fem_angle).max()),
                   max_vertex_error=float(max(errors)), emu_vertex_error=[float(e) for e in errors])
    progress(f"  time over the frames: EMU {summary['emu_time_s']:.2f} s (its solves "
             f"{summary['emu_solve_s']:.2f} s, its error estimates {summary['emu_error_estimate_s']:.2f} s), "
             f"FEM {fem_s:.2f} s")
    progress(f"  EMU vs FEM: elbow angle within "
             f"{summary['max_angle_difference_deg']:.2f} degrees, vertex error <= "
             f"{summary['max_vertex_error']:.2e} of the diagonal ({mode})")
    corrected = [summary["fem_corrected"][k] for k in done]
    if any(corrected):
        progress(f"  {sum(corrected)} of {len(done)} frames FEM-corrected (EMU's estimate missed the accuracy; "
                 "its answer corrected by FEM Newton steps instead of a re-solve)")
    # the estimate of EMU's own answers (a corrected frame's is the last correction step's length)
    est = [summary["emu_error_estimate"][k] for k in done]
    ratios = [e / t for e, t, c in zip(est, errors, corrected) if e is not None and t > 1e-6 and not c]
    if ratios:
        summary["estimate_over_true"] = [float(min(ratios)), float(max(ratios))]
        progress(f"  EMU's own error estimate (no FEM needed): max {max(e for e in est if e is not None):.2e}; "
                 f"estimate / true error {min(ratios):.2f} to {max(ratios):.2f} over the frames not corrected")
    return fem_angle
