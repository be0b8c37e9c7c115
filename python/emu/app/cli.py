"""The ``emu`` command line.

    emu demo [--out DIR] [--resolution R] [--frames N] [--alpha A] [--no-fem] [--threads T]
    emu compare [--out DIR] [--tets N] [--threads T] [--woodbury]
    emu solve MESH --activation NAME=A [NAME=A ...] [--free-bones BONE ...] [--method emu|fem] [--accuracy E]
              [--out FILE.vtu]     (A: a fraction of the muscle's maximum, as in scene files;
                                    --absolute-activation NAME=A for absolute values)
    emu run SCENE.toml [--out DIR] [--accuracy E]
    emu sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N] [--threads T]
    emu info [MESH]
    emu data [NAME ...]

MESH is a mesh file or the name of one of the authors' research scenes
(simple_joint, big_muscle, realistic_biceps: downloaded on first use, see
emu.datasets).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings

import numpy as np

from ..build import datasets
from ..solve.advice import method_hint
from ..core.geometry import vertex_error
from ..io.mesh import load_scene
from ..model.joints import joint_loop, loop_note
from ..io.vtk import write_solution
from ..core.runtime import __version__
from ..core.runtime import info as runtime_info
from ..core.runtime import set_threads
from ..build.scenes import fusiform
from ..solve.options import CHOICES, OPTIONS, check_options, parse_option
from ..solve.solver import Solver
from .demo import run_demo
from .run import accuracy_summary, run_scene
from .scenefile import load_scene_file


def _mesh_defects(mesh: str, num_tets: int) -> list:
    """The surface defects emu mesh recorded in report.json beside ``mesh``
    (a mesh file), where that report describes this mesh (the same number of
    tets); [] otherwise."""
    try:
        with open(os.path.join(os.path.dirname(os.path.abspath(mesh)), "report.json")) as f:
            report = json.load(f)
    except (OSError, ValueError):
        return []
    return list(report.get("defects", [])) if report.get("tets") == num_tets else []


def _print_info(args):
    i = runtime_info()
    print(f"emu {i['version']}")
    print(f"BLAS: {i['config']}")
    print(f"      kernel {i['kernel']}")
    print(f"      {i['library']}, {i['blas_threads']} thread(s); OpenMP: {i['omp_threads']} thread(s); "
          f"threads: {i['threads']}")
    if not args.mesh:
        return 0
    spec = None
    mesh_file = None if args.mesh.endswith((".toml", ".json")) else mesh_path(args.mesh)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if mesh_file is None:
            spec = load_scene_file(args.mesh)
            scene, mesh_file = spec.scene, spec.mesh_path
        else:
            scene = load_scene(mesh_file, warn=False, **_parse_parts(args.kind, args.fibers, args.weld))
    print(scene)
    _print_mesh_defects(scene, mesh_file)
    _print_parts(scene)
    _print_bones(scene, set(spec.bones) if spec is not None else set())
    if spec is not None:
        print(f"  frames: {spec.frames} x {spec.dt:g} s; solver: {spec.solver or 'defaults'}")
        if spec.dynamics is not None:
            d = spec.dynamics
            print(f"  dynamics: time steps of {d.dt:g} s, {d.integrator}, mass damping {d.mass_damping:g} / s")
        for name, curve in spec.curves.items():
            kind = "per frame" if curve.per_frame is not None else f"{len(curve.keys)} keys, {curve.interpolation}"
            print(f"  activation {name}: {kind}, {'normalised' if curve.normalized else 'absolute'}")
    ids, _ = scene.model_pins()
    print(f"  fixed vertices (pins, fixed bones): {len(ids)}")
    m, n = len(scene.model_tets), len(scene.points)
    print(f"  memory estimate: FEM ~{(m * 144 * 8 + n * 3 * 60 * 8) / 2**20:.0f} MiB, "
          f"EMU ~{(m * 9 * 8 * 12 + m * 81 * 8 * 2) / 2**20:.0f} MiB plus the factor")
    try:
        scene.validate()
    except ValueError as e:   # what emu solve / emu run would refuse, said here first
        print(f"  cannot be solved as it is: {e}")
        return 1
    return 0


def _print_mesh_defects(scene, mesh_file: str) -> None:
    """emu info: the mesh report, surface defects, cracks and loose contacts."""
    for line in scene.mesh_report.lines():
        print("  " + line)
    for defect in (_mesh_defects(mesh_file, len(scene.tets)) if mesh_file else []):
        print(f"  surface defect (found by emu mesh): {defect}")
    for a, b, n in scene.cracks():
        print(f"  crack: {a} and {b} touch at {n} vertex pair(s) they do not share (--weld joins them)")
    for soft, bone, n, area in scene.loose_contacts():
        print(f"  loose: {soft} lies on {bone} over {n} surface triangle(s), area {area:.3g}, sharing no "
              "vertex there (not attached there: mesh the parts as one with emu mesh, or turn contact on "
              "if it slides)")


def _print_parts(scene) -> None:
    """emu info: each part, its material and a muscle's attachments."""
    for p in scene.parts.values():
        e = scene.points[scene.tets[p.tets]]
        volume = float(np.abs(np.linalg.det(e[:, 1:] - e[:, :1])).sum() / 6.0)
        print(f"  part {p.name}: {p.kind}, {len(p.tets)} tets, E = {p.youngs:g}, nu = {p.poisson:g}, "
              f"density {p.density:g}, mass {p.density * volume:.4g} (volume {volume:.4g})")
        if p.kind == "muscle":
            att = scene.attachments(p.name)
            desc = [f"{b} ({len(v)} vertices)" for b, v in att.items()]
            desc += [f"{b} through {t} ({len(v)} vertices)"
                     for b, (t, v) in scene.tendon_attachments(p.name).items() if b not in att]
            desc = ", ".join(desc) or "none (pins only)"
            print(f"    attachments: {desc}")


def _print_bones(scene, scripted: set) -> None:
    """emu info: the bones (moved, scripted or fixed), their joints and a loop of joints."""
    bones = [p.name for p in scene.parts.values() if p.kind == "bone"]
    if not bones:
        return
    movable = set(scene.movable_bones)
    desc = ", ".join(f"{b} ({'moved by the muscles' if b in movable else 'scripted' if b in scripted else 'fixed'})"
                     for b in bones)
    print(f"  bones: {desc}")
    for j in scene.joints():
        where = "a declared point" if j.declared else \
            f"vertices {j.vertices.tolist()}" if len(j.vertices) <= 4 else f"{len(j.vertices)} vertices"
        extra = f", axis {np.round(j.axis, 6).tolist()}" if j.axis is not None else ""
        print(f"  joint {j.bones[0]} - {j.bones[1]}: {j.kind} at {where}, "
              f"centre {np.round(j.centre, 6).tolist()}{extra}")
    if (pair := joint_loop(scene.joints(), scene.movable_bones)) is not None:
        print(f"  loop: {loop_note(pair)}")


def _demo(args):
    if args.threads:
        set_threads(args.threads)
    if args.resolution < 1 or args.frames < 2:
        raise ValueError("--resolution must be >= 1 and --frames >= 2")
    summary = run_demo(args.out, resolution=args.resolution, frames=args.frames, alpha=args.alpha,
                       compare_fem=not args.no_fem, accuracy=args.accuracy)
    return 0 if summary["all_converged"] else 1


def _compare(args):
    if args.threads:
        set_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)
    scene = fusiform(tets=args.tets, pins=("proximal",))
    act = {"belly": args.activation}
    info = runtime_info()
    print(f"emu compare: fusiform muscle, {len(scene.tets)} tets ({len(scene.parts['belly'].tets)} muscle, "
          f"{len(scene.parts['tendons'].tets)} tendon), {len(scene.points)} vertices, proximal end pinned")
    print(f"activation a = {args.activation:g} on the belly; threads {info['omp_threads']}; BLAS {info['config']}")
    runs = [("fem", {})]
    runs.append(("emu", dict(alpha=args.alpha, step="newton-krylov")))
    if args.woodbury:
        runs.append(("emu", dict(alpha=args.alpha, step="woodbury", max_iterations=3000)))
    sols = []
    for method, kw in runs:
        t0 = time.perf_counter()
        solver = Solver(scene, method, **kw)
        sol = solver.solve(act)
        sols.append(sol)
        path = os.path.join(args.out, f"{sol.label}.vtu")
        write_solution(path, scene, sol, activation=act, fibers=solver.fibers)
        print(f"  {sol.summary()}  [{time.perf_counter() - t0:.2f} s wall] -> {path}", flush=True)
    fem = sols[0]
    summary = {"tets": len(scene.tets), "vertices": len(scene.points), "threads": info["omp_threads"],
               "blas": info["config"], "activation": args.activation, "alpha": args.alpha, "results": {}}
    tip = scene.vertex_sets["distal"]
    length0 = float(np.mean(scene.points[tip, 2]))   # the distal end face lies at z = length
    for sol in sols:
        err = vertex_error(sol, fem)
        shortening = 1.0 - float(np.mean(sol.positions[tip, 2])) / length0
        summary["results"][sol.label] = dict(converged=sol.converged, iterations=sol.iterations,
                                             cg_iterations=sol.cg_iterations, time_s=sol.time_s,
                                             solve_s=sol.solve_time_s,
                                             setup_s=sol.setup_time_s, vertex_error_to_fem=err,
                                             shortening=shortening)
        if sol is not fem:
            print(f"  {sol.label}: vertex error to FEM = {err:.2e} of the bounding-box diagonal "
                  f"(alpha = {args.alpha:g} mu)")
    print(f"  the muscle shortened by {100 * summary['results']['fem']['shortening']:.1f}% (FEM)")
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(f"wrote {args.out}/*.vtu (open in ParaView; cell data part, fiber, activation, J; point data "
          f"displacement) and summary.json")
    return 0 if all(s.converged for s in sols if s.settings.get("step") != "woodbury") else 1


def _parse_activation(items, option="--activation"):
    act = {}
    for it in items or []:
        if "=" not in it:
            raise ValueError(f"{option} expects NAME=VALUE, got {it!r}")
        k, v = it.split("=", 1)
        try:
            act[k] = float(v)
        except ValueError:
            raise ValueError(f"{option} {k}: {v!r} is not a number") from None
    return act


def _activation(scene, args) -> dict:
    """{muscle: absolute a} from --activation (fractions of each muscle's
    maximum, as scene files take them) and --absolute-activation."""
    normalised = _parse_activation(args.activation)
    absolute = _parse_activation(args.absolute_activation, "--absolute-activation")
    for name, v in normalised.items():
        if name in absolute:
            raise ValueError(f"muscle '{name}' is given by both --activation and --absolute-activation; give one")
        if name not in scene.muscles:
            raise ValueError(f"--activation: no muscle named '{name}' (muscles: {', '.join(scene.muscles) or 'none'})")
        if not 0.0 <= v <= 1.0:
            raise ValueError(f"--activation {name}={v:g}: a fraction of the muscle's maximum activation "
                             f"({scene.parts[name].max_activation:g}) between 0 and 1; for an absolute value use "
                             f"--absolute-activation {name}={v:g}")
    out = {name: v * scene.parts[name].max_activation for name, v in normalised.items()}
    out.update(absolute)
    return out


def _parse_parts(kinds, fibers, weld=False) -> dict:
    """load_scene's kinds= and fibers= from --kind NAME=KIND and --fibers
    (file | laplace for every muscle, or NAME=file|laplace|x,y,z per muscle)."""
    out = {}
    if kinds:
        out["kinds"] = {}
        for it in kinds:
            if "=" not in it:
                raise SystemExit(f"--kind expects NAME=KIND (muscle, tendon or bone), got {it!r}")
            k, v = it.split("=", 1)
            out["kinds"][k] = v
    per_part = {}
    for it in fibers or []:
        if "=" not in it:
            if it not in ("file", "laplace"):
                raise SystemExit(f"--fibers expects file, laplace or NAME=file|laplace|x,y,z, got {it!r}")
            out["other_fibers"] = it
            continue
        k, v = it.split("=", 1)
        if v in ("file", "laplace"):
            per_part[k] = v
        else:
            try:
                per_part[k] = [float(c) for c in v.split(",")]
            except ValueError:
                raise SystemExit(f"--fibers {k}: {v!r} is not file, laplace or a direction x,y,z") from None
    if per_part:
        out["fibers"] = per_part
    elif "other_fibers" in out:
        out["fibers"] = out.pop("other_fibers")
    if weld:
        out["weld"] = True
    return out


def mesh_path(arg: str) -> str:
    """A mesh file, or the converted file of a research scene named ``arg``
    (fetched on first use)."""
    if os.path.exists(arg) or arg not in datasets.names():
        return arg
    return datasets.path(arg, progress=lambda m: print(f"emu: {m}", file=sys.stderr))


def _data(args):
    return datasets.fetch_main(args.names or None)


def _solve(args):
    options = _options(args)   # a mistyped option fails before the mesh is read
    if args.threads:
        set_threads(args.threads)
    scene = load_scene(mesh_path(args.mesh), free_bones=args.free_bones or (),
                       **_parse_parts(args.kind, args.fibers, args.weld))
    print(scene)
    act = _activation(scene, args)
    kw = dict(alpha=args.alpha, step=args.step) if args.method == "emu" else {}
    if args.accuracy is not None:
        kw["accuracy"] = args.accuracy
    for name, value in options.items():
        if kw.get(name) is not None:
            raise ValueError(f"{name} is given twice (--{name.replace('_', '-')} and --option); give it once")
        kw[name] = value
    solver = Solver(scene, args.method, **kw)
    sol = solver.solve(act)
    print(sol.summary())
    hint = method_hint(scene, args.method)
    if hint:
        print(hint)
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        write_solution(args.out, scene, sol, activation=act, fibers=solver.fibers)
        print(f"wrote {args.out}")
        if not args.no_preview:
            from ..io.plots import contact_sheet, default_view

            picture = os.path.splitext(args.out)[0] + ".png"
            rest_act = {m: 0.0 for m in scene.muscles}
            solved_act = scene.normalised_activation(act)
            contact_sheet(picture, scene, [scene.points, sol.positions], titles=["rest", "solved"],
                          activations=[rest_act, solved_act], view=default_view(scene))
            print(f"wrote {picture} (rest and solved; --no-preview skips it)")
    return 0 if sol.converged and sol.accuracy_reached is not False else 1


def _run(args):
    if os.path.isdir(args.scene):
        found = sorted(f for f in os.listdir(args.scene) if f.endswith((".toml", ".json")))
        raise ValueError(f"{args.scene} is a folder: give one scene file"
                         + (f", e.g. {os.path.join(args.scene, found[0])}" if found else ""))
    spec = load_scene_file(args.scene)
    if args.method is not None and args.method != spec.solver.get("method", "emu"):
        spec.solver["method"] = args.method
        # the scene file's options for the other method do not apply (-O ones are still checked)
        dropped = [k for k in list(spec.solver) if k in OPTIONS and args.method not in OPTIONS[k].methods]
        for k in dropped:
            del spec.solver[k]
        if dropped:
            print(f"--method {args.method}: leaving out the scene file's {', '.join(dropped)} "
                  f"(options of {'EMU' if args.method == 'fem' else 'FEM'} only)")
    if args.threads:
        spec.solver["threads"] = args.threads
    if args.accuracy is not None:
        spec.solver["accuracy"] = args.accuracy
    spec.solver.update(_options(args))
    check_options(spec.solver.get("method", "emu"), spec.solver.get("step", OPTIONS["step"].default),
                  {k: v for k, v in spec.solver.items() if k != "method"})
    if args.no_preview:
        spec.output["preview"] = False
    if args.usd:
        spec.output["usd"] = True
    log = run_scene(spec, args.out)
    wrote = [w for w, on in (("frame_*.vtu + series.pvd (ParaView)", spec.output.get("vtu", True)),
                             ("frame_*.obj (Blender)", spec.output.get("obj", True)), ("log.json", True),
                             ("run.usd (USD)", spec.output["usd"] and log["frames"]),
                             ("preview.png", spec.output["preview"] and log["frames"])) if on]
    print(f"wrote {args.out or spec.output['dir']}: {', '.join(wrote)}")
    if summary := accuracy_summary(log):
        print(f"accuracy: {summary}")
    if log["interrupted"]:
        return 130
    return 0 if all(f["converged"] and f.get("accuracy_reached") is not False for f in log["frames"]) else 1


def _sweep(args):
    from .sweep import sweep

    try:
        rows = sweep(args.sweep, args.out, scheduler=args.scheduler, workers=args.workers, threads=args.threads)
    except KeyboardInterrupt:
        return 130
    except ImportError as e:
        print(f"emu: error: {e}", file=sys.stderr)
        return 2
    return 0 if all(r["status"] == "done" for r in rows) else 1


def _mesh(args):
    from ..build.author import author, format_report, write_authored

    try:
        result = author(args.parts, quiet=not args.verbose, threads=args.threads or 0)
    except ImportError as e:
        print(f"emu: error: {e}", file=sys.stderr)
        return 2
    paths = write_authored(result, args.out)
    print(format_report(result.report))
    print(f"wrote {paths['mesh']}, {paths['scene']} (a scene file: emu info / emu run it), "
          f"{paths['picture']} (the parts, joints and attachments)")
    return 0


def _option_argument(p, more: str = ""):
    p.add_argument("--option", "-O", action="append", default=[], metavar="NAME=VALUE",
                   help="any solver option (docs/guide/options.md), e.g. -O rtol_grad=1e-8 -O eigen_filter=abs"
                        + more)


def _options(args) -> dict:
    """{option: value} of the --option NAME=VALUE arguments (each once)."""
    out = {}
    for text in args.option:
        name, value = parse_option(text)
        if name in out:
            raise ValueError(f"--option {name} is given twice; give it once")
        out[name] = value
    return out


def _part_options(p):
    """--kind and --fibers: what a labelled mesh's parts are (emu.io.load_scene)."""
    p.add_argument("--kind", nargs="*", metavar="NAME=KIND",
                   help="a part's kind: muscle, tendon or bone (default: the scene.json beside the mesh, else muscle)")
    p.add_argument("--fibers", nargs="*", metavar="SPEC",
                   help="muscles' fibres: file (the mesh's 'fiber' cell data) or laplace (between the two bone "
                        "attachments) for every muscle, or NAME=file|laplace|x,y,z for one")
    p.add_argument("--weld", action="store_true",
                   help="merge vertices at the same point (parts meshed apart; vertex ids change)")


THREADS_HELP = ("solver threads, at least 1 (default: OMP_NUM_THREADS, else automatic: all cores, fewer "
                "where other processes keep cores busy)")


def _threads(text: str) -> int:
    """--threads: a positive integer (argparse's type)."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number of threads, at least 1, got {text!r} "
                                         "(leave it out for the default)")
    return n


def main(argv=None):
    ap = argparse.ArgumentParser(prog="emu", description="EMU muscle simulation (and its FEM reference)")
    ap.add_argument("--version", action="version", version=f"emu {__version__}")
    sub = ap.add_subparsers(dest="cmd", required=True)
    _add_demo(sub)
    _add_solve(sub)
    _add_run(sub)
    _add_tools(sub)
    args = ap.parse_args(argv)
    previous = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        return args.func(args)
    except (ValueError, OSError, NotImplementedError, ImportError, datasets.DatasetError) as e:
        print(f"emu: error: {e}", file=sys.stderr)
        return 2
    finally:
        warnings.showwarning = previous


def _add_demo(sub) -> None:
    """The subcommands for the built-in demo and the fusiform comparison."""
    d = sub.add_parser("demo", help="the built-in arm: a flexor then an extensor swing the forearm about the "
                                    "elbow; frames, PNG contact sheet, angle plot, EMU vs FEM")
    d.add_argument("--out", default="emu_out", help="output folder (default: emu_out)")
    d.add_argument("--resolution", type=int, default=3, help="the arm's mesh: 1 (1.8k tets), 2 (3.8k) or 3 (6.4k, the default); others are meshed once and cached")
    d.add_argument("--frames", type=int, default=25, help="frames over the 2 s sequence (default 25)")
    d.add_argument("--alpha", type=float, default=None,
                   help="EMU alpha relative to the muscles' shear modulus, fixed (default: chosen for --accuracy)")
    d.add_argument("--accuracy", type=float, default=None,
                   help="vertex error to FEM wanted (default 0.01 unless --alpha is given)")
    d.add_argument("--no-fem", action="store_true", help="skip the FEM reference solves")
    d.add_argument("--threads", type=_threads, default=None, help=THREADS_HELP)
    d.set_defaults(func=_demo)
    d = sub.add_parser("compare", help="contract a fusiform muscle with FEM and EMU at one activation, write VTU")
    d.add_argument("--out", default="emu_compare", help="output folder (default: emu_compare)")
    d.add_argument("--tets", type=int, default=8000, help="approximate tet count (default 8000)")
    d.add_argument("--activation", type=float, default=5e4, help="absolute activation a (default 5e4)")
    d.add_argument("--alpha", type=float, default=100.0, help="EMU alpha relative to the muscle's shear modulus")
    d.add_argument("--threads", type=_threads, default=None, help=THREADS_HELP)
    d.add_argument("--woodbury", action="store_true", help="also run the paper's Woodbury quasi-Newton step")
    d.set_defaults(func=_compare)


def _add_solve(sub) -> None:
    """The subcommands for one solve of a labelled mesh."""
    s = sub.add_parser("solve", help="solve a labelled mesh at one activation (bones fixed unless --free-bones)")
    s.add_argument("mesh", help="a labelled mesh file, or a research scene name (" + ", ".join(datasets.names()) + ")")
    s.add_argument("--free-bones", nargs="*", metavar="BONE", help="bones the muscles move")
    _part_options(s)
    s.add_argument("--activation", nargs="*", metavar="NAME=A",
                   help="activations as fractions (0-1) of each muscle's maximum, as in scene files")
    s.add_argument("--absolute-activation", nargs="*", metavar="NAME=A",
                   help="absolute activations (the stress a fully shortened fibre adds, in the mesh's units)")
    s.add_argument("--method", choices=["emu", "fem"], default="emu",
                   help="emu (the default) or fem, the reference Newton solver of the same energy")
    s.add_argument("--step", choices=CHOICES["step"], default=CHOICES["step"][0],
                   help="EMU's step (default newton-krylov; the others are for comparison: docs/guide/options.md)")
    s.add_argument("--alpha", type=float, default=None,
                   help="EMU alpha relative to the softest muscle's shear modulus, fixed (default: chosen for "
                        "--accuracy, 0.01 unless --alpha is given)")
    s.add_argument("--accuracy", type=float, default=None,
                   help="vertex error to FEM wanted (0.01: 1%% of the diagonal): picks alpha, stops when steps no "
                        "longer matter")
    s.add_argument("--threads", type=_threads, default=None, help=THREADS_HELP)
    _option_argument(s)
    s.add_argument("--out", default=None, help="write the result here (.vtu) and a preview picture beside it (.png)")
    s.add_argument("--no-preview", action="store_true", help="with --out: do not write the preview picture")
    s.set_defaults(func=_solve)


def _add_run(sub) -> None:
    """The subcommands for a scene file's frames, and sweeps of them."""
    r = sub.add_parser("run", help="run a scene file (TOML/JSON) over its frames")
    r.add_argument("scene", help="the scene file (TOML or JSON; docs/guide/scene-files.md)")
    r.add_argument("--out", default=None, help="output folder (default: the scene's output.dir)")
    r.add_argument("--method", choices=["emu", "fem"], default=None,
                   help="override the scene file's solver.method (default: the file's, else emu)")
    r.add_argument("--threads", type=_threads, default=None, help=THREADS_HELP)
    r.add_argument("--accuracy", type=float, default=None,
                   help="override the scene file's solver.accuracy (vertex error to FEM wanted, e.g. 0.01)")
    _option_argument(r, "; overrides the scene file's [solver] table")
    r.add_argument("--no-preview", action="store_true", help="do not write preview.png (output.preview = false)")
    r.add_argument("--usd", action="store_true", help="also write run.usd, one animated USD stage (output.usd = "
                                                      "true; needs pip install emu[usd])")
    r.set_defaults(func=_run)
    w = sub.add_parser("sweep", help="run many cases of a scene file (a grid or list of scene-file keys) on "
                                     "Dask: a local cluster or a scheduler; results.csv, one folder per case")
    w.add_argument("sweep", help="the sweep file (TOML/JSON): base scene file, [grid] and/or [[cases]]")
    w.add_argument("--out", required=True, help="output folder (re-running it skips finished cases)")
    w.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (default: a local "
                                                     "cluster on this machine)")
    w.add_argument("--workers", type=int, default=None, help="local workers (default: cores // threads)")
    w.add_argument("--threads", type=_threads, default=None, help="solver threads per case (default: the sweep "
                                                             "file's, 1)")
    w.set_defaults(func=_sweep)


def _add_tools(sub) -> None:
    """The subcommands for meshing, info and data."""
    m = sub.add_parser("mesh", help="mesh one closed surface per part (a parts file, TOML) into one labelled "
                                    "tet mesh and a scene file (fTetWild)")
    m.add_argument("parts", help="the parts file: [mesh] tets or edge_length, [[part]] name/surface/kind, "
                                 "optional [[joint]] (emu.author)")
    m.add_argument("--out", required=True,
                   help="output folder: mesh.vtu, scene.json, scene.toml, report.json, mesh.png")
    m.add_argument("--threads", type=_threads, default=None, help="mesher threads (default: all cores)")
    m.add_argument("--verbose", action="store_true", help="show the mesher's own progress")
    m.set_defaults(func=_mesh)
    i = sub.add_parser("info", help="BLAS, threads; with a mesh or scene file: parts, attachments, defects, "
                                    "memory estimate")
    i.add_argument("mesh", nargs="?", help="a labelled mesh (.vtu, ...) or a scene file (.toml, .json)")
    _part_options(i)
    i.set_defaults(func=_print_info)
    g = sub.add_parser("data", help="download and convert the authors' research scenes ahead of use "
                                    "(default: all); EMU_DATA_DIR: a local copy instead of the network")
    g.add_argument("names", nargs="*", metavar="NAME", help=", ".join(datasets.names()))
    g.set_defaults(func=_data)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings on the command line: the message, without Python's source line."""
    print(f"emu: warning: {message}", file=file or sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
