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
from ..model.bones import bone_angle
from ..io.obj import boundary_faces, part_groups, write_obj
from ..io.plots import contact_sheet, default_view, frame_title, motion_views
from ..io.vtk import write_pvd, write_solution
from ..core.runtime import info as runtime_info
from ..solve.solver import Solver
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
    files = _RunFiles(spec, out, solver)
    info = runtime_info()
    log = {"scene": spec.source, "method": solver.method, "settings": solver.settings, "blas": info["config"],
           "threads": info["omp_threads"], "setup_s": solver.setup_time_s,
           "parts": [{"id": k, "name": p.name, "kind": p.kind, "tets": len(p.tets)}
                     for k, p in enumerate(spec.scene.parts.values())],
           "frames": [], "interrupted": False}
    t_start = time.perf_counter()
    progress(f"{spec.scene}; {spec.frames} frame(s), {solver.method} (setup {solver.setup_time_s:.2f} s)")
    log["method_hint"] = hint = method_hint(spec.scene, solver.method, sequence=spec.frames > 1,
                                               dynamics=spec.dynamics is not None)
    if hint:
        progress(hint)
    try:
        loads = spec.frame_loads()
        for k, sol in enumerate(solve_frames(solver, loads, dynamics=spec.dynamics)):
            act = loads[k].activation
            files.frame(k, sol, act)
            log["frames"].append(_frame_entry(spec, k, sol, act))
            if on_frame is not None:
                on_frame(k, sol)
            left = (time.perf_counter() - t_start) / (k + 1) * (spec.frames - k - 1)
            progress(_progress_line(k, spec.frames, sol, left))
    except KeyboardInterrupt:
        log["interrupted"] = True
        progress(f"interrupted: kept {len(log['frames'])} finished frame(s)")
    finally:
        files.close(log)
    return log


class _RunFiles:
    """What a run writes as its frames come: a VTU per frame and the .pvd
    series, OBJ surfaces, run.usd, log.json and preview.png (the frames the
    preview shows kept until the end), each as spec.output asks."""

    def __init__(self, spec: SceneSpec, out: str, solver):
        self.spec, self.out, self.fibers = spec, out, solver.fibers
        self.faces = self.groups = self.usd = None
        if spec.output.get("obj", True):
            self.faces, faces_tet = boundary_faces(spec.scene.tets, return_tets=True)
            self.groups = part_groups(spec.scene, faces_tet)
        if spec.output.get("usd", False):
            from ..io.usd import UsdWriter

            self.usd = UsdWriter(os.path.join(out, "run.usd"), spec.scene, spec.dt,
                                 meters_per_unit=spec.output.get("meters_per_unit", 1.0), fibers=solver.fibers)
        self.pvd, self.kept, self.last = [], {}, None
        self.want_preview = spec.output.get("preview", True)
        self.picks = set(np.linspace(0, spec.frames - 1, min(PREVIEW_FRAMES, spec.frames)).round().astype(int).tolist())

    def frame(self, k: int, sol, act: dict) -> None:
        spec, name = self.spec, f"frame_{k:04d}"
        if spec.output.get("vtu", True):
            write_solution(os.path.join(self.out, name + ".vtu"), spec.scene, sol, activation=act, fibers=self.fibers)
            self.pvd.append((k * spec.dt, name + ".vtu"))
        if self.faces is not None:
            write_obj(os.path.join(self.out, name + ".obj"), sol.positions, self.faces, self.groups)
        if self.usd is not None:
            self.usd.add_frame(k, sol.positions, spec.scene.normalised_activation(act), velocities=sol.velocities)
        if self.want_preview and k in self.picks:
            self.kept[k] = sol.positions.copy()
        self.last = sol

    def close(self, log: dict) -> None:
        """The series, the USD stage, log.json and the preview (an interrupted run's shows where it stopped)."""
        if self.pvd:
            write_pvd(os.path.join(self.out, "series.pvd"), self.pvd)
        if self.usd is not None and self.usd.frames:
            self.usd.save()
        with open(os.path.join(self.out, "log.json"), "w") as f:
            json.dump(log, f, indent=2, default=float)
        if self.want_preview and log["frames"]:
            last = len(log["frames"]) - 1
            if last not in self.kept and self.last is not None:
                self.kept[last] = self.last.positions.copy()
            _preview(os.path.join(self.out, "preview.png"), self.spec, self.kept, log)


def _frame_entry(spec: SceneSpec, k: int, sol, act: dict) -> dict:
    """log.json's record of frame k."""
    angles = {name: curve.value(k, k * spec.dt) for name, (_, _, curve) in spec.bones.items()}
    for name in spec.scene.movable_bones:
        angles[name] = bone_angle(spec.scene, sol.positions, name)
    return {"frame": k, "time": k * spec.dt, "activation": act,
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
            "inverted_tets": sol.inverted_tets, "contact": sol.contact,
            "max_speed": None if sol.velocities is None else float(np.linalg.norm(sol.velocities, axis=1).max())}


def _progress_line(k: int, frames: int, sol, left: float) -> str:
    """The progress line of frame k: its solve, its estimate and how it was reached, the time left."""
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
    return (f"frame {k + 1}/{frames}: {sol.iterations} it" + (f" ({sol.cg_iterations} CG)" if sol.cg_iterations else "")
            + f", E = {sol.energy:.6g}, {sol.time_s:.2f} s{est}, ~{left:.0f} s left{flag}")


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
