"""``emu sweep``: many runs of one scene file on Dask (dask.distributed).

A sweep file (TOML or JSON):

    base = "arm.toml"                  # the scene file every case starts from (relative to this file)
    plot = "angle:forearm"             # the PNG's quantity: "angle:<bone>" (last frame, degrees),
                                       # "error_estimate" (largest), "time_s" (the frames' solves,
                                       # estimates included), "solve_s" (their iterations), "iterations"
    threads = 1                        # solver threads per case (OpenMP and BLAS)

    [grid]                             # every combination of these scene-file keys (dotted paths)
    "solver.alpha" = [30.0, 100.0, 300.0]
    "materials.flexor.youngs" = [3e4, 6e4]
    "activation.flexor.keys" = [[[0.0, 0.0], [1.0, 0.5]], [[0.0, 0.0], [1.0, 1.0]]]

    [[cases]]                          # and/or a list of cases, each a table of keys
    "solver.method" = "fem"

Each case is an ``emu run`` of the base scene with its keys set, in its own
folder under the output (scene.json, the frames, log.json); results.csv
holds one row per case (its parameters, status, error, frames, iterations,
times, the largest error estimate, the plotted quantity, its folder), written
as each case finishes, so Ctrl-C or a crash keeps every finished case, and
running the same sweep again skips the cases that ran to their end (status
"done" or "not converged"; failed ones are tried again). A case that fails is recorded with its error; the others go on.

Dask: a LocalCluster on this machine by default (workers x threads per case
never more than its cores), or any running scheduler by address. Dask is an
optional extra: ``pip install emu[sweep]``.
"""
from __future__ import annotations

import copy
import csv
import hashlib
import itertools
import json
import math
import os
import time
import traceback

from .scenefile import SceneFileError, _read

__all__ = ["sweep", "load_sweep", "SweepError", "RESULT_COLUMNS"]

RESULT_COLUMNS = ("case", "status", "error", "frames", "converged_frames", "iterations", "cg_iterations",
                  "time_s", "solve_s", "error_estimate_s", "wall_s", "max_error_estimate", "plot_value", "output")
PLOTS = ("time_s", "solve_s", "iterations", "error_estimate")
# statuses of a case that ran to its end (a re-run skips it): every frame
# converged, or some did not (the case says so; running it again would not change that)
FINISHED = ("done", "not converged")


class SweepError(ValueError):
    """A sweep file that does not follow the schema, or settings that cannot run."""


def _dask():
    try:
        import dask.distributed as dd
    except ImportError as e:
        raise ImportError("emu sweep runs on Dask, which is not installed: pip install 'emu[sweep]' "
                          "(or pip install 'dask[distributed]')") from e
    return dd


def load_sweep(path) -> dict:
    """Read a sweep file: {"base": absolute scene-file path, "cases": [{key: value}], "plot", "threads"}."""
    path = os.fspath(path)
    try:
        data = _read(path)
    except SceneFileError as e:
        raise SweepError(str(e)) from None
    known = {"base", "plot", "threads", "grid", "cases"}
    unknown = set(data) - known
    if unknown:
        raise SweepError(f"{path}: unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(known))})")
    if "base" not in data or not isinstance(data["base"], str):
        raise SweepError(f"{path}: 'base' must name the scene file every case starts from")
    base = data["base"] if os.path.isabs(data["base"]) else os.path.join(os.path.dirname(os.path.abspath(path)),
                                                                            data["base"])
    if not os.path.exists(base):
        raise FileNotFoundError(f"{path}: base scene file not found: {base}")
    grid = data.get("grid", {})
    listed = data.get("cases", [])
    if not isinstance(grid, dict) or not all(isinstance(v, list) and v for v in grid.values()):
        raise SweepError(f"{path}: [grid] maps scene-file keys to non-empty lists of values")
    if not isinstance(listed, list) or not all(isinstance(c, dict) for c in listed):
        raise SweepError(f"{path}: [[cases]] must be a list of tables of scene-file keys")
    cases = [dict(zip(grid, values)) for values in itertools.product(*grid.values())] if grid else []
    if listed:
        cases = [{**g, **c} for g in (cases or [{}]) for c in listed]
    if not cases:
        raise SweepError(f"{path}: no cases: give a [grid] and/or [[cases]]")
    plot = data.get("plot", "solve_s")
    if not (plot in PLOTS or (isinstance(plot, str) and plot.startswith("angle:") and len(plot) > 6)):
        raise SweepError(f"{path}: plot must be one of {', '.join(PLOTS)} or 'angle:<bone>', got {plot!r}")
    threads = data.get("threads", 1)
    if not (isinstance(threads, int) and threads >= 1):
        raise SweepError(f"{path}: threads must be an integer >= 1, got {threads!r}")
    return {"base": base, "cases": cases, "plot": plot, "threads": threads}


def case_id(params: dict) -> str:
    """A short stable name for a case's parameters (its folder and results row)."""
    return hashlib.sha1(json.dumps(params, sort_keys=True).encode()).hexdigest()[:10]


def case_scene(base: str, params: dict) -> dict:
    """The base scene file's data with the case's dotted keys set (mesh.path made absolute)."""
    data = copy.deepcopy(_read(base))
    mesh = data.get("mesh", {})
    if isinstance(mesh, dict) and isinstance(mesh.get("path"), str) and not os.path.isabs(mesh["path"]):
        mesh["path"] = os.path.join(os.path.dirname(os.path.abspath(base)), mesh["path"])
    for key, value in params.items():
        parts = key.split(".")
        node = data
        for p in parts[:-1]:
            child = node.setdefault(p, {})
            if not isinstance(child, dict):
                raise SweepError(f"case key {key!r}: {p!r} is not a table in the base scene file")
            node = child
        node[parts[-1]] = value
    return data


def check_cases(base: str, cases: list, plot: str) -> None:
    """Build every case's scene (without solving) and check the plotted bone,
    so a mistake in any case stops the sweep before the first runs: raises
    SweepError listing each case that would fail, with its parameters."""
    import tempfile
    import warnings

    from .scenefile import load_scene_file

    problems = []
    with tempfile.TemporaryDirectory() as tmp:
        for params in cases:
            path = os.path.join(tmp, "scene.json")
            try:
                with open(path, "w") as f:
                    json.dump(case_scene(base, params), f)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    spec = load_scene_file(path)
                if plot.startswith("angle:"):
                    bones = list(spec.bones) + spec.scene.movable_bones
                    if plot[6:] not in bones:
                        raise SweepError(f"plot {plot!r}: no movable or scripted bone {plot[6:]!r} "
                                         f"(bones: {', '.join(bones) or 'none'})")
            except (ValueError, FileNotFoundError, KeyError) as e:
                problems.append(f"case {json.dumps(params, sort_keys=True)}: {e}")
    if problems:
        raise SweepError(f"{len(problems)} of {len(cases)} case(s) would fail, nothing was run:\n  "
                         + "\n  ".join(problems))


def run_case(base: str, params: dict, out: str, plot: str, threads: int) -> dict:
    """One case in a worker: its scene file written to out/scene.json and run
    there (emu run); returns its results row. Never raises: a failure is the
    row's status and error."""
    row = {"case": case_id(params), "status": "failed", "error": "", "output": out, **_param_columns(params)}
    t0 = time.perf_counter()
    try:
        from ..core.runtime import set_threads
        from .run import run_scene
        from .scenefile import load_scene_file

        set_threads(threads)
        os.makedirs(out, exist_ok=True)
        scene_path = os.path.join(out, "scene.json")
        with open(scene_path, "w") as f:
            json.dump(case_scene(base, params), f, indent=1)
        spec = load_scene_file(scene_path)
        with open(os.path.join(out, "run.log"), "w") as logf:
            log = run_scene(spec, out, progress=lambda line: print(line, file=logf, flush=True))
        frames = log["frames"]
        estimates = [f["error_estimate"] for f in frames if f.get("error_estimate") is not None]
        row.update(frames=len(frames), converged_frames=sum(f["converged"] for f in frames),
                   iterations=sum(f["iterations"] for f in frames),
                   cg_iterations=sum(f["cg_iterations"] for f in frames),
                   time_s=sum(f["time_s"] for f in frames),
                   solve_s=sum(f["solve_s"] for f in frames),
                   error_estimate_s=sum(f.get("error_estimate_s", 0.0) for f in frames),
                   max_error_estimate=max(estimates) if estimates else "")
        row["plot_value"] = _plot_value(plot, frames, row)
        # finished only once everything the row reports is in it
        row["status"] = "done" if all(f["converged"] for f in frames) else "not converged"
    except Exception as e:  # recorded: the sweep goes on
        row["error"] = f"{type(e).__name__}: {e}"
        with open(os.path.join(out, "error.txt"), "w") as f:
            f.write(traceback.format_exc())
    row["wall_s"] = time.perf_counter() - t0
    return row


def _param_columns(params: dict) -> dict:
    return {f"param:{k}": json.dumps(v) if not isinstance(v, (int, float, str)) else v for k, v in params.items()}


def _plot_value(plot: str, frames: list, row: dict):
    if plot.startswith("angle:"):
        bone = plot[6:]
        angles = frames[-1].get("bone_angles_deg", {})
        if bone not in angles:
            raise SweepError(f"plot {plot!r}: no movable bone {bone!r} (movable: {', '.join(angles) or 'none'})")
        return angles[bone]
    if plot == "error_estimate":
        return row["max_error_estimate"]
    return row[plot]


def _read_results(path: str) -> dict:
    if not os.path.exists(path):
        return {}
    with open(path, newline="") as f:
        return {r["case"]: r for r in csv.DictReader(f)}


def _write_results(path: str, rows: list):
    columns = list(RESULT_COLUMNS) + sorted({k for r in rows for k in r if k.startswith("param:")})
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    os.replace(tmp, path)   # a crash mid-write never leaves a torn table


def sweep(sweep_file, out: str, *, scheduler: str | None = None, workers: int | None = None,
          threads: int | None = None, progress=print) -> list:
    """Run every case of a sweep file on Dask; returns the results rows (dicts).

    scheduler  address of a running Dask scheduler ("tcp://host:8786"); None: a
               LocalCluster of ``workers`` processes on this machine
    workers    local workers (None: the machine's cores // threads)
    threads    solver threads per case (None: the sweep file's, default 1); on a
               local cluster workers x threads must not exceed the cores
    Finished cases (status "done" or "not converged" in out/results.csv) are skipped; Ctrl-C
    cancels the running cases, keeps the table of the finished ones and
    re-raises KeyboardInterrupt.
    """
    dd = _dask()
    spec = load_sweep(sweep_file)
    threads = spec["threads"] if threads is None else int(threads)
    if threads < 1:
        raise SweepError(f"threads must be >= 1, got {threads}")
    workers = _local_workers(workers, threads) if scheduler is None else workers
    os.makedirs(out, exist_ok=True)
    table = os.path.join(out, "results.csv")
    previous = _read_results(table)
    cases = spec["cases"]
    ids = [case_id(c) for c in cases]
    if len(set(ids)) != len(ids):
        raise SweepError("two cases have the same parameters; each case must differ")
    rows = {i: previous[i] for i in ids if i in previous and previous[i].get("status") in FINISHED}
    todo = [(i, c) for i, c in zip(ids, cases) if i not in rows]
    check_cases(spec["base"], [c for _, c in todo], spec["plot"])
    progress(f"emu sweep: {len(cases)} case(s), {len(rows)} done already, {len(todo)} to run; "
             f"{threads} solver thread(s) per case")
    if todo:
        _run_cases(dd, spec, todo, ids, rows, out, threads, scheduler, workers, progress)
    out_rows = [rows[i] for i in ids if i in rows]
    _write_results(table, out_rows)
    png = os.path.join(out, "sweep.png")
    if plot_results(png, out_rows, spec["plot"]):
        progress(f"wrote {table} and {png}")
    else:
        progress(f"wrote {table}")
    return out_rows


def _local_workers(workers, threads: int) -> int:
    """A local cluster's worker count: given, or the cores // threads; never more
    workers x threads than the machine has cores."""
    cores = os.cpu_count() or 1
    workers = max(1, cores // threads) if workers is None else int(workers)
    if workers < 1:
        raise SweepError(f"workers must be >= 1, got {workers}")
    if workers * threads > cores:
        raise SweepError(f"{workers} workers x {threads} solver threads would oversubscribe this machine's "
                         f"{cores} cores; use --workers {max(1, cores // threads)} or fewer threads")
    return workers


def _run_cases(dd, spec, todo, ids, rows, out, threads, scheduler, workers, progress) -> None:
    """The cases still to run, on Dask (a local cluster or a scheduler): each
    finished row into ``rows`` and results.csv as it comes; Ctrl-C cancels the rest."""
    table = os.path.join(out, "results.csv")
    if scheduler is None:
        cluster = dd.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = dd.Client(cluster)
        where = f"local cluster, {workers} worker(s)"
    else:
        cluster, client = None, dd.Client(scheduler)
        where = f"scheduler {scheduler}"
    progress(f"  on {where}")
    t0 = time.perf_counter()
    futures = {client.submit(run_case, spec["base"], c, os.path.join(out, f"case_{i}"), spec["plot"], threads,
                             key=f"emu-case-{i}", pure=False): i for i, c in todo}
    failed = done = 0
    try:
        for fut in dd.as_completed(futures):
            row = fut.result()
            rows[row["case"]] = row
            done += row["status"] in FINISHED
            failed += row["status"] not in FINISHED
            _write_results(table, [rows[i] for i in ids if i in rows])
            finished = done + failed
            left = (time.perf_counter() - t0) / finished * (len(todo) - finished)
            running = min(len(todo) - finished, sum(client.nthreads().values()))
            msg = f"  case {row['case']}: {row['status']}" + (f" ({row['error']})" if row["error"] else "")
            progress(f"{msg}; {finished}/{len(todo)} finished ({done} done, {failed} failed), "
                     f"{running} running, ~{left:.0f} s left")
    except KeyboardInterrupt:
        client.cancel(list(futures))
        progress(f"interrupted: kept {done + failed} finished case(s) in {table}")
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def plot_results(path: str, rows: list, quantity: str) -> bool:
    """A PNG of the quantity against the swept parameters: against the first
    numeric parameter that varies most, one line per value of the other varying
    ones. False if no numeric parameter varies."""
    from ..io.plots import _pyplot

    keys = sorted({k for r in rows for k in r if k.startswith("param:")})
    pts = []
    for r in rows:
        try:
            y = float(r.get("plot_value", ""))
        except (TypeError, ValueError):
            continue
        if math.isfinite(y):
            pts.append((r, y))
    varying = [k for k in keys if len({str(r.get(k)) for r, _ in pts}) > 1]
    numeric = sorted((k for k in varying if all(_is_number(r.get(k)) for r, _ in pts)),
                     key=lambda k: -len({str(r.get(k)) for r, _ in pts}))
    if not pts or not numeric:
        return False
    # against the numeric parameter with the most values; a line per value of the other varying ones
    x_key, others = numeric[0], [k for k in varying if k != numeric[0]]
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    groups = {}
    for r, y in pts:
        label = ", ".join(f"{k[6:]}={r.get(k)}" for k in others)
        groups.setdefault(label, []).append((float(r[x_key]), y))
    for label, xy in sorted(groups.items()):
        xy.sort()
        ax.plot([a for a, _ in xy], [b for _, b in xy], "o-", label=label or None)
    if len(groups) > 1 or next(iter(groups)):
        ax.legend(fontsize=7)
    ax.set_xlabel(x_key[6:])
    ax.set_ylabel(quantity)
    if all(a > 0 for xy in groups.values() for a, _ in xy) and \
            max(a for xy in groups.values() for a, _ in xy) > 10 * min(a for xy in groups.values() for a, _ in xy):
        ax.set_xscale("log")
    ax.set_title(f"emu sweep: {quantity} over {len(pts)} case(s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _is_number(v) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False
