"""Running a scene over its frames: warm-started solves, per-frame files, a log.

Outputs in the folder: frame_NNNN.vtu per frame and series.pvd (ParaView),
frame_NNNN.obj surfaces (Blender), log.json (per-frame solver statistics),
preview.png (up to eight frames, shaded, per-part colours) and, asked for,
run.usd (one animated USD stage: a prim per part, a time sample per frame). A run first
removes what an earlier run wrote there (those names only). Ctrl-C stops after
keeping every finished frame (and the series, log and preview).
"""
from __future__ import annotations

import glob
import json
import os
import re
import time

import numpy as np

from ..solve.advice import method_hint
from ..bones import bone_angle
from ..io.obj import boundary_faces, part_groups, write_obj
from ..io.plots import contact_sheet, default_view, frame_title, motion_views
from ..io.vtk import write_pvd, write_solution
from ..runtime import info as runtime_info
from ..solve import Solver
from ..solve.frames import solve_frames
from .scenefile import SceneSpec

__all__ = ["run_scene", "clear_run", "RUN_OUTPUTS"]

# What a run writes into its folder (and a rerun removes first).
RUN_OUTPUTS = re.compile(r"frame_\d{4,}\.(vtu|obj)|series\.pvd|log\.json|preview\.png|run\.usd")
PREVIEW_FRAMES = 8


def clear_run(out_dir: str) -> int:
    """Remove the files an earlier run wrote into out_dir (RUN_OUTPUTS names
    only; anything else stays). Returns how many were removed."""
    removed = 0
    for path in glob.glob(os.path.join(out_dir, "*")):
        if os.path.isfile(path) and RUN_OUTPUTS.fullmatch(os.path.basename(path)):
            os.remove(path)
            removed += 1
    return removed


def _preview(path, spec: SceneSpec, kept: dict, log: dict) -> None:
    """preview.png: the kept frames side by side, looking along the first
    hinge (or the mesh's thinnest side), muscles coloured by activation."""
    scene = spec.scene
    frames = sorted(kept)
    entries = [log["frames"][k] for k in frames]
    acts = [scene.normalised_activation(e["activation"]) for e in entries]
    titles = [frame_title(e["frame"], e["time"], e["bone_angles_deg"]) for e in entries]
    positions = [kept[k] for k in frames]
    view = spec.output.get("view") or default_view(scene)
    # a second view where the motion leaves the first's plane, unless the file chose its view
    views = [view] if spec.output.get("view") else motion_views(scene, positions, view)
    contact_sheet(path, scene, positions, titles=titles, activations=acts, views=views)


def run_scene(spec: SceneSpec, out_dir: str | None = None, progress=print, on_frame=None) -> dict:
    """Solve every frame of a scene file, warm-starting each from the last.
    on_frame(k, solution) is called after each frame (e.g. to keep positions)."""
    out = out_dir or spec.output["dir"]
    # the solver first: a scene it refuses leaves no folder (and an earlier run's files in place)
    solver = Solver(spec.scene, **spec.solver)
    os.makedirs(out, exist_ok=True)
    cleared = clear_run(out)
    if cleared:
        progress(f"removed {cleared} file(s) an earlier run wrote in {out}")
    faces = groups = None
    if spec.output.get("obj", True):
        faces, faces_tet = boundary_faces(spec.scene.tets, return_tets=True)
        groups = part_groups(spec.scene, faces_tet)
    info = runtime_info()
    log = {"scene": spec.source, "method": solver.method, "settings": solver.settings, "blas": info["config"],
           "threads": info["omp_threads"], "setup_s": solver.setup_time_s,
           "parts": [{"id": k, "name": p.name, "kind": p.kind, "tets": len(p.tets)}
                     for k, p in enumerate(spec.scene.parts.values())],
           "frames": [], "interrupted": False}
    pvd = []
    prev = None
    usd = None
    if spec.output.get("usd", False):
        from ..io.usd import UsdWriter

        usd = UsdWriter(os.path.join(out, "run.usd"), spec.scene, spec.dt,
                        meters_per_unit=spec.output.get("meters_per_unit", 1.0), fibers=solver.fibers)
    want_preview = spec.output.get("preview", True)
    picks = set(np.linspace(0, spec.frames - 1, min(PREVIEW_FRAMES, spec.frames)).round().astype(int).tolist())
    kept = {}
    t_start = time.perf_counter()
    progress(f"{spec.scene}; {spec.frames} frame(s), {solver.method} (setup {solver.setup_time_s:.2f} s)")
    hint = method_hint(spec.scene, solver.method, sequence=spec.frames > 1)
    if hint:
        progress(hint)
    log["method_hint"] = hint
    try:
        for k, sol in enumerate(solve_frames(solver, spec.frame_loads())):
            act = spec.activation(k)
            prev = sol
            name = f"frame_{k:04d}"
            if spec.output.get("vtu", True):
                write_solution(os.path.join(out, name + ".vtu"), spec.scene, sol, activation=act,
                               fibers=solver.fibers)
                pvd.append((k * spec.dt, name + ".vtu"))
            if faces is not None:
                write_obj(os.path.join(out, name + ".obj"), sol.positions, faces, groups)
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
                                  "error_estimate_certified": sol.error_estimate_certified,
                                  "settled_by_fem": _settled(sol), "error_estimate_note": sol.error_estimate_note,
                                  "inverted_tets": sol.inverted_tets, "contact": sol.contact})
            if usd is not None:
                usd.add_frame(k, sol.positions, spec.scene.normalised_activation(act))
            if want_preview and k in picks:
                kept[k] = sol.positions.copy()
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
            if _settled(sol):
                est += " (estimate not certified: settled by FEM)"
            elif sol.corrected:
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
        if usd is not None and usd.frames:
            usd.save()
        with open(os.path.join(out, "log.json"), "w") as f:
            json.dump(log, f, indent=2, default=float)
        if want_preview and log["frames"]:
            last = len(log["frames"]) - 1
            if last not in kept and prev is not None:   # interrupted: show where it stopped
                kept[last] = prev.positions.copy()
            _preview(os.path.join(out, "preview.png"), spec, kept, log)
    return log


def _settled(sol) -> bool:
    """EMU's answer settled by a FEM solve (its estimate did not certify itself)."""
    return bool(sol.corrected and sol.error_estimate_certified is False)


def accuracy_summary(log) -> str:
    """One line on the frames whose accuracy was not EMU's own: settled by FEM
    (the estimate did not certify itself) or not reached; "" where none."""
    frames = log["frames"]
    settled = sum(bool(f.get("settled_by_fem")) for f in frames)
    missed = sum(f.get("accuracy_reached") is False for f in frames)
    parts = []
    if settled:
        parts.append(f"{settled} of {len(frames)} frame(s) settled by a FEM solve (EMU's error estimate did not "
                     "certify itself there; where most frames are, method = \"fem\" under [solver] is likely faster)")
    if missed:
        parts.append(f"{missed} of {len(frames)} frame(s) did not reach the accuracy asked for (log.json: "
                     "error_estimate_note)")
    return "; ".join(parts)
