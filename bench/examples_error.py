"""Every example scene file with its own settings (EMU's default accuracy 0.01),
each frame solved by EMU, by strict FEM (the reference) and by the two FEM
baselines at EMU's accuracy (FEM Newton, and FEM on a lagged factor), each
warm-started from its own previous frame: EMU's vertex error to strict FEM, its
own estimate, EMU's time against the faster baseline's (by the example's
total), and the FEM factorisations EMU's estimates made.

    python bench/examples_error.py [examples/*.toml] [--emu-step-fraction F] [--docs DIR]

Prints the summary table (the README's examples table). --docs DIR also
writes DIR/examples.md (per example: a picture of EMU's frames and the
per-frame table) and DIR/images/examples/<name>.png.
--emu-step-fraction F: EMU's accuracy stopping rule at F of the target
instead of the scene's (Solver(step_fraction=F)).
"""
from __future__ import annotations

import argparse
import glob
import os
import subprocess
import time
import warnings

import numpy as np

import emu
from emu.app.scenefile import load_scene_file
from emu._core import testing
from emu.io.plots import contact_sheet, default_view, frame_title

HERE = os.path.dirname(os.path.abspath(__file__))
PICTURE_FRAMES = 8


def _first_comment(path) -> str:
    """The example's own description: its leading comment lines, joined."""
    lines = []
    with open(path) as f:
        for line in f:
            if not line.startswith("#"):
                break
            text = line[1:].strip()
            if text.startswith("emu run") or text.startswith("python "):
                continue
            lines.append(text)
    return " ".join(lines)


def run_example(path, extra: dict) -> dict:
    """Solve every frame with EMU (the scene's settings), strict FEM and the FEM
    baselines at EMU's accuracy."""
    spec = load_scene_file(path)
    emu_solver = emu.Solver(spec.scene, **{**spec.solver, "method": "emu", **extra})
    fem_solver = emu.Solver(spec.scene, "fem", rtol_grad=1e-9)
    accuracy = emu_solver.accuracy or 0.01
    baselines = {"FEM": emu.Solver(spec.scene, "fem", accuracy=accuracy)}
    if spec.scene.contact is None:   # (the lagged factor does not take contact)
        baselines["lagged FEM"] = emu.Solver(spec.scene, "fem", accuracy=accuracy, lagged_factor=True)
    if spec.dynamics is not None:
        return run_time_steps(path, spec, emu_solver, fem_solver, baselines)
    base_s = dict.fromkeys(baselines, 0.0)
    rows, frames = [], {}
    picks = set(np.linspace(0, spec.frames - 1, min(PICTURE_FRAMES, spec.frames)).round().astype(int).tolist())
    loads = spec.frame_loads()
    runs = {name: emu.solve_frames(s, loads) for name, s in (("emu", emu_solver), ("strict", fem_solver),
                                                             *baselines.items())}
    for k in range(spec.frames):
        act = spec.activation(k)
        sols = {name: next(run) for name, run in runs.items()}
        se, sf = sols["emu"], sols["strict"]
        base_frame = {name: sols[name].time_s for name in baselines}
        for name in baselines:
            base_s[name] += base_frame[name]
        angles = {b: emu.bone_angle(spec.scene, se.positions, b) for b in spec.scene.movable_bones}
        rows.append({"frame": k, "time": k * spec.dt, "emu_s": se.time_s, "estimate_s": se.error_estimate_time_s,
                     "strict_s": sf.time_s, "base_s": base_frame, "error": emu.vertex_error(se, sf),
                     "estimate": se.error_estimate, "alpha": se.settings["alpha"], "corrected": se.corrected,
                     "settled": se.corrected and se.error_estimate_certified is False, "angles": angles,
                     "activation": spec.scene.normalised_activation(act),
                     "converged": se.converged and sf.converged})
        if k in picks:
            frames[k] = se.positions.copy()
    mode = f"accuracy {emu_solver.accuracy:g}" if emu_solver.accuracy else f"alpha {emu_solver.alpha:g}"
    fastest = min(base_s, key=base_s.get)
    for x in rows:
        x["fem_s"] = x["base_s"][fastest]
    return {"path": path, "spec": spec, "rows": rows, "frames": frames, "mode": mode, "baseline": fastest,
            "factorizations": getattr(emu_solver._estimator.fem, "factorizations", 0)}


def run_time_steps(path, spec, emu_solver, fem_solver, baselines) -> dict:
    """A scene file with [dynamics]: every frame a time step. Each EMU step is
    checked against strict FEM's step from EMU's own state (the same positions,
    velocities and load: the error its estimate estimates), and EMU's
    trajectory against strict FEM's own (errors carried forward); the
    baselines run their own trajectories for the times. Per frame also the
    movable bones' angles and the kinetic and total energies (elastic, active,
    gravity's and kinetic, without the inertia term) of both trajectories."""
    dyn, scene = spec.dynamics, spec.scene
    masses = emu.vertex_masses(scene)
    reference = emu.Solver(scene, "fem", rtol_grad=1e-9)   # FEM's steps from EMU's states
    base_s = dict.fromkeys(baselines, 0.0)
    rows, frames = [], {}
    loads = spec.frame_loads()
    runs = {name: emu.solve_frames(s, loads, dynamics=dyn) for name, s in (("emu", emu_solver),
                                                                            ("strict", fem_solver),
                                                                            *baselines.items())}
    state = emu.MotionState.at_rest(scene.points)   # EMU's state before each step

    def energies(load, x, v):
        kinetic = 0.5 * float(np.sum(masses[:, None] * v ** 2))
        return kinetic, kinetic + float(testing.energy(fem_solver._core, load, x))
    for k, f in enumerate(loads):
        sols = {name: next(run) for name, run in runs.items()}
        se, sf = sols["emu"], sols["strict"]
        step = reference.solve(f.activation, normalized=f.normalized, gravity=f.gravity,
                               pin_positions=f.pin_positions, bone_poses=f.bone_poses or None,
                               initial=state.positions, inertia=dyn.inertia(state))
        state = dyn.advance(state, se.positions)
        for name in baselines:
            base_s[name] += sols[name].time_s
        load = fem_solver.load_case(f.activation, f.normalized, f.gravity, f.pin_positions, f.bone_poses or None)
        angles = {b: emu.bone_angle(scene, se.positions, b) for b in scene.movable_bones}
        rows.append({"frame": k, "time": k * spec.dt, "emu_s": se.time_s, "estimate_s": se.error_estimate_time_s,
                     "strict_s": sf.time_s, "base_s": {name: sols[name].time_s for name in baselines},
                     "error": emu.vertex_error(se, step), "trajectory": emu.vertex_error(se, sf),
                     "estimate": se.error_estimate, "alpha": se.settings["alpha"], "corrected": se.corrected,
                     "settled": se.corrected and se.error_estimate_certified is False, "angles": angles,
                     "fem_angles": {b: emu.bone_angle(scene, sf.positions, b) for b in scene.movable_bones},
                     "energy": energies(load, se.positions, se.velocities),
                     "fem_energy": energies(load, sf.positions, sf.velocities),
                     "activation": scene.normalised_activation(f.activation),
                     "converged": se.converged and sf.converged and step.converged})
        frames[k] = se.positions.copy()
    picks = motion_picks(rows, scene.movable_bones)
    frames = {k: frames[k] for k in picks}
    fastest = min(base_s, key=base_s.get)
    for x in rows:
        x["fem_s"] = x["base_s"][fastest]
    # the energies' floor: the last frame's load at rest (its static equilibrium)
    f = loads[-1]
    rest = emu.Solver(scene, "fem", rtol_grad=1e-9).solve(f.activation, normalized=f.normalized, gravity=f.gravity,
                                                         pin_positions=f.pin_positions, bone_poses=f.bone_poses or None)
    load = fem_solver.load_case(f.activation, f.normalized, f.gravity, f.pin_positions, f.bone_poses or None)
    mode = f"accuracy {emu_solver.accuracy:g}" if emu_solver.accuracy else f"alpha {emu_solver.alpha:g}"
    return {"path": path, "spec": spec, "rows": rows, "frames": frames, "mode": mode + f", {dyn.integrator} steps",
            "baseline": fastest, "factorizations": getattr(emu_solver._estimator.fem, "factorizations", 0),
            "rest_energy": float(testing.energy(fem_solver._core, load, rest.positions)),
            "rest_angles": {b: emu.bone_angle(scene, rest.positions, b) for b in scene.movable_bones}}


def motion_picks(rows, bones) -> list:
    """The frames a time-stepped example's picture shows: the first, the turning
    points of the first movable bone's swing (its angle's local extremes), the
    last; without movable bones, evenly over the first half."""
    n = len(rows)
    if not bones:
        return sorted(set(np.linspace(0, n // 2, PICTURE_FRAMES - 1).round().astype(int).tolist()) | {n - 1})
    a = [x["angles"][bones[0]] for x in rows]
    turns = [k for k in range(1, n - 1) if (a[k] - a[k - 1]) * (a[k + 1] - a[k]) < 0]
    return sorted({0, n - 1, *turns[:PICTURE_FRAMES - 2]})


def motion_plot(png: str, r) -> None:
    """A time-stepped example's motion: the movable bones' angles and the
    kinetic and total energies over time, EMU's trajectory against strict FEM's."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, bones = r["rows"], r["spec"].scene.movable_bones
    t = [x["time"] for x in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for b in bones:
        axes[0].plot(t, [x["fem_angles"][b] for x in rows], "k-", lw=2.5, alpha=0.35, label=f"{b}, FEM")
        axes[0].plot(t, [x["angles"][b] for x in rows], "C0.-", ms=3, lw=1, label=f"{b}, EMU")
        axes[0].axhline(r["rest_angles"][b], color="0.5", ls=":", lw=1, label=f"{b} at rest (last load)")
    axes[0].set(xlabel="t (s)", ylabel="angle (deg)", title="bone angles")
    for key, style, name in (("fem_energy", "-", "FEM"), ("energy", ".-", "EMU")):
        kinetic = [x[key][0] for x in rows[1:]]
        total = [x[key][1] - r["rest_energy"] for x in rows[1:]]
        axes[1].semilogy(t[1:], kinetic, "C1" + style, ms=3, label=f"kinetic, {name}")
        axes[1].semilogy(t[1:], total, "C2" + style, ms=3, label=f"total above rest, {name}")
    axes[1].set(xlabel="t (s)", ylabel="energy (J)", title="energies (log scale)")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def summary_row(r) -> str:
    rows = r["rows"]
    te, tf = sum(x["emu_s"] for x in rows), sum(x["fem_s"] for x in rows)
    test = sum(x["estimate_s"] for x in rows)
    worst = max(x["error"] for x in rows)
    worst_est = max((x["estimate"] or 0.0) for x in rows)
    alphas = [x["alpha"] for x in rows]
    settled = sum(x["settled"] for x in rows)
    return (f"| {os.path.basename(r['path'])} | {len(r['spec'].scene.tets)} | {len(rows)} | {r['mode']} | "
            f"{te:.2f} ({test:.2f}) | {tf:.2f} ({r['baseline']}) | {tf / te:.2f}x | {worst:.2e} | {worst_est:.2e} | "
            f"{settled} | {min(alphas):.0f}-{max(alphas):.0f} | {r['factorizations']} |")


def write_page(results, docs_dir, header: str) -> str:
    """docs_dir/examples.md and one picture per example under images/examples."""
    img_dir = os.path.join(docs_dir, "images", "examples")
    os.makedirs(img_dir, exist_ok=True)
    out = ["# Examples, each checked against FEM", "",
           "Every scene file in `examples/`, run as `emu run` runs it (EMU at the file's settings, "
           "`accuracy = 0.01` unless it says otherwise) and, frame by frame, by FEM Newton to the strict "
           "tolerance (|g| <= 1e-9 |g0|) from its own previous frame. *error* is the largest vertex "
           "distance between EMU's and strict FEM's answers over the rest mesh's bounding-box diagonal; "
           "*estimate* is EMU's own estimate of it (no FEM solve needed); *settled*: EMU's estimate did not "
           "certify itself and the answer was settled by a FEM solve. Times are each method's whole solve "
           "of the frame (EMU's includes its estimate); *FEM s* is the faster of the two FEM baselines at "
           "the same accuracy (FEM Newton, FEM on a lagged factor; named per example), each warm-started "
           "from its own previous frame. Pictures show EMU's frames.", "",
           f"Produced by `python bench/examples_error.py --docs docs` ({header}).", ""]
    for r in results:
        name = os.path.splitext(os.path.basename(r["path"]))[0]
        spec, rows = r["spec"], r["rows"]
        png = os.path.join(img_dir, name + ".png")
        ks = sorted(r["frames"])
        titles = [frame_title(k, rows[k]["time"], rows[k]["angles"]) for k in ks]
        contact_sheet(png, spec.scene, [r["frames"][k] for k in ks], titles=titles,
                      activations=[rows[k]["activation"] for k in ks],
                      view=spec.output.get("view") or default_view(spec.scene))
        te, tf = sum(x["emu_s"] for x in rows), sum(x["fem_s"] for x in rows)
        steps = "trajectory" in rows[0]   # a time-stepped example ([dynamics])
        motion = []
        if steps:
            motion_plot(os.path.join(img_dir, name + "_motion.png"), r)
            motion = [f"![{name}: angles and energies](images/examples/{name}_motion.png)", "",
                      "*error* is EMU's step against strict FEM's step from EMU's own state (the "
                      "error its estimate estimates); *trajectory* is EMU's distance to strict FEM's own "
                      "trajectory, errors carried forward.", ""]
        out += [f"## {name}", "", _first_comment(r["path"]), "",
                f"`emu run examples/{name}.toml`: {len(spec.scene.tets):,} tets, {len(rows)} frames; "
                f"EMU {te:.2f} s, {r['baseline']} {tf:.2f} s in all; EMU's largest error "
                f"{100 * max(x['error'] for x in rows):.2f}% (its estimate "
                f"{100 * max((x['estimate'] or 0.0) for x in rows):.2f}%).", "",
                f"![{name}](images/examples/{name}.png)", "", *motion,
                "| frame | t (s) | " + "".join(f"{m} | " for m in spec.scene.muscles)
                + "".join(f"{b} (deg) | " for b in spec.scene.movable_bones)
                + "EMU s | FEM s | error | " + ("trajectory | " if steps else "") + "estimate | alpha |",
                "|" + "---|" * (7 + steps + len(spec.scene.muscles) + len(spec.scene.movable_bones))]
        for x in rows:
            est = "-" if x["estimate"] is None else f"{100 * x['estimate']:.2f}%"
            flag = " (settled)" if x["settled"] else " (FEM-corrected)" if x["corrected"] else ""
            out.append(f"| {x['frame']} | {x['time']:.2f} | "
                       + "".join(f"{x['activation'].get(m, 0.0):.2f} | " for m in spec.scene.muscles)
                       + "".join(f"{x['angles'][b]:+.1f} | " for b in spec.scene.movable_bones)
                       + f"{x['emu_s']:.3f} | {x['fem_s']:.3f} | {100 * x['error']:.2f}% | "
                       + (f"{100 * x['trajectory']:.2f}% | " if steps else "")
                       + f"{est}{flag} | {x['alpha']:.0f} |")
        out.append("")
    page = os.path.join(docs_dir, "examples.md")
    with open(page, "w") as f:
        f.write("\n".join(out))
    return page


def main(argv=None):
    parser = argparse.ArgumentParser(description="every example's frames: EMU as shipped against strict FEM and "
                                     "the faster FEM baseline")
    parser.add_argument("paths", nargs="*", help="scene files (default: every examples/*.toml)")
    parser.add_argument("--docs", metavar="DIR", help="write DIR/examples.md (pictures, per-frame tables)")
    parser.add_argument("--emu-step-fraction", type=float, help="EMU's step_fraction option")
    a = parser.parse_args(argv)
    extra = {} if a.emu_step_fraction is None else {"step_fraction": a.emu_step_fraction}
    docs = a.docs
    paths = a.paths or sorted(glob.glob(os.path.join(HERE, "..", "examples", "*.toml")))
    warnings.simplefilter("ignore")
    i = emu.info()
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=HERE).stdout.strip()
    except OSError:
        commit = "?"
    header = (f"emu {i['version']} at {commit}; BLAS {i['config']}; OpenMP threads {i['omp_threads']}; "
              f"{time.strftime('%Y-%m-%d')}")
    print(header + "\n")
    print("| example | tets | frames | EMU settings | EMU s (of it estimates s) | FEM s (the faster baseline) | "
          "FEM / EMU | max true error | max estimate | frames settled | alpha range | estimate's factorisations |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    results = []
    for path in paths:
        r = run_example(path, extra)
        print(summary_row(r), flush=True)
        results.append(r)
    if docs:
        print(f"wrote {write_page(results, docs, header)}")


if __name__ == "__main__":
    main()
