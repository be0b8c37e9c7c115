"""Running a scene over its frames: warm-started solves, per-frame files, a log.

Outputs in the folder: frame_NNNN.vtu per frame and series.pvd (ParaView),
frame_NNNN.obj surfaces (Blender), log.json (per-frame solver statistics).
Ctrl-C stops after keeping every finished frame (and the series and log).
"""
from __future__ import annotations

import json
import os
import time

from ..advice import method_hint
from ..bones import bone_angle
from ..io.obj import boundary_faces, write_obj
from ..io.vtk import write_pvd, write_solution
from ..runtime import info as runtime_info
from ..solve import Solver
from .scenefile import SceneSpec

__all__ = ["run_scene"]


def run_scene(spec: SceneSpec, out_dir: str | None = None, progress=print, on_frame=None) -> dict:
    """Solve every frame of a scene file, warm-starting each from the last.
    on_frame(k, solution) is called after each frame (e.g. to keep positions)."""
    out = out_dir or spec.output["dir"]
    os.makedirs(out, exist_ok=True)
    solver = Solver(spec.scene, **spec.solver)
    faces = boundary_faces(spec.scene.tets) if spec.output.get("obj", True) else None
    info = runtime_info()
    log = {"scene": spec.source, "method": solver.method, "settings": solver.settings, "blas": info["config"],
           "threads": info["omp_threads"], "setup_s": solver.setup_time_s, "frames": [], "interrupted": False}
    pvd = []
    prev = None
    t_start = time.perf_counter()
    progress(f"{spec.scene}; {spec.frames} frame(s), {solver.method} (setup {solver.setup_time_s:.2f} s)")
    hint = method_hint(spec.scene, solver.method, sequence=spec.frames > 1)
    if hint:
        progress(hint)
    log["method_hint"] = hint
    try:
        for k in range(spec.frames):
            act = spec.activation(k)
            sol = solver.solve(act, bone_poses=spec.bone_poses(k) or None, initial=prev)
            prev = sol
            name = f"frame_{k:04d}"
            if spec.output.get("vtu", True):
                write_solution(os.path.join(out, name + ".vtu"), spec.scene, sol, activation=act,
                               fibers=solver.fibers)
                pvd.append((k * spec.dt, name + ".vtu"))
            if faces is not None:
                write_obj(os.path.join(out, name + ".obj"), sol.positions, faces)
            angles = {name: curve.value(k, k * spec.dt) for name, (_, _, curve) in spec.bones.items()}
            for name in spec.scene.movable_bones:
                angles[name] = bone_angle(spec.scene, sol.positions, name)
            log["frames"].append({"frame": k, "time": k * spec.dt, "activation": act,
                                  "bone_angles_deg": angles, "converged": sol.converged,
                                  "status": sol.status, "iterations": sol.iterations,
                                  "cg_iterations": sol.cg_iterations, "energy": sol.energy,
                                  "rel_grad_norm": sol.grad_norm / sol.grad_norm0 if sol.grad_norm0 else 0.0,
                                  "time_s": sol.time_s, "solve_s": sol.solve_time_s,
                                  "alpha": sol.settings.get("alpha"),
                                  "error_estimate": sol.error_estimate,
                                  "error_estimate_s": sol.error_estimate_time_s,
                                  "accuracy_reached": sol.accuracy_reached, "fem_corrected": sol.corrected,
                                  "inverted_tets": sol.inverted_tets, "contact": sol.contact})
            if on_frame is not None:
                on_frame(k, sol)
            elapsed = time.perf_counter() - t_start
            left = elapsed / (k + 1) * (spec.frames - k - 1)
            flag = "" if sol.converged else f"  NOT converged: {sol.status}"
            est = "" if sol.error_estimate is None else f", est. error to FEM {sol.error_estimate:.1e}"
            if sol.inverted_tets:
                est += f", {sol.inverted_tets} inverted tet(s)"
            if sol.accuracy_reached is False:
                est += f" ({sol.error_estimate_note})"
            if sol.corrected:
                est += " (FEM-corrected)"
            if sol.contact is not None:
                est += f", {sol.contact['pairs']} contact pair(s), gap {sol.contact['min_distance']:.2g}"
            progress(f"frame {k + 1}/{spec.frames}: {sol.iterations} it"
                     + (f" ({sol.cg_iterations} CG)" if sol.cg_iterations else "")
                     + f", E = {sol.energy:.6g}, {sol.time_s:.2f} s{est}, ~{left:.0f} s left{flag}")
    except KeyboardInterrupt:
        log["interrupted"] = True
        progress(f"interrupted: kept {len(log['frames'])} finished frame(s)")
    finally:
        if pvd:
            write_pvd(os.path.join(out, "series.pvd"), pvd)
        with open(os.path.join(out, "log.json"), "w") as f:
            json.dump(log, f, indent=2, default=float)
    return log
