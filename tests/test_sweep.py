"""emu sweep on Dask: a 2-worker local cluster runs a small sweep; a failing
case is recorded and the others finish; an interrupted sweep resumes without
re-running finished cases; without Dask the command says how to get it."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("dask.distributed", reason="emu sweep needs Dask (pip install emu[sweep])")

import emu  # noqa: E402
from emu.app.sweep import SweepError, case_id, load_sweep  # noqa: E402

SCENE = """
[mesh.arm]
resolution = 1
[solver]
method = "emu"
[frames]
count = 2
dt = 1.0
[activation.flexor]
keys = [[0.0, 0.0], [1.0, 0.5]]
"""


def write(tmp_path, grid, extra=""):
    (tmp_path / "arm.toml").write_text(SCENE)
    lines = ['base = "arm.toml"', 'plot = "angle:forearm"', extra, "[grid]"]
    lines += [f'"{k}" = {json.dumps(v)}' for k, v in grid.items()]
    path = tmp_path / "sweep.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def rows(out):
    with open(out / "results.csv", newline="") as f:
        return {r["case"]: r for r in csv.DictReader(f)}


def test_two_workers_run_a_sweep_and_record_a_failing_case(tmp_path):
    # alpha = -1 is refused by the solver: that case fails, the others finish
    path = write(tmp_path, {"solver.alpha": [30.0, 300.0, -1.0], "materials.flexor.youngs": [3e4, 6e4]})
    out = tmp_path / "out"
    lines = []
    result = emu.sweep(path, str(out), workers=2, progress=lines.append)
    assert "on local cluster, 2 worker(s)" in "\n".join(lines)
    table = rows(out)
    assert len(table) == len(result) == 6
    failed = [r for r in table.values() if r["status"] == "failed"]
    assert len(failed) == 2 and all(r["param:solver.alpha"] == "-1.0" for r in failed)
    assert all("alpha must be a positive number" in r["error"] for r in failed)
    done = [r for r in table.values() if r["status"] == "done"]
    assert len(done) == 4
    for r in done:
        folder = Path(r["output"])
        assert (folder / "log.json").exists() and (folder / "series.pvd").exists() and (folder / "run.log").exists()
        log = json.loads((folder / "log.json").read_text())
        assert len(log["frames"]) == 2 and float(r["plot_value"]) == pytest.approx(
            log["frames"][-1]["bone_angles_deg"]["forearm"])
        scene = json.loads((folder / "scene.json").read_text())
        assert scene["solver"]["alpha"] == float(r["param:solver.alpha"])
        assert scene["materials"]["flexor"]["youngs"] == float(r["param:materials.flexor.youngs"])
    # a softer flexor bends the elbow further (the parameter reached the solve)
    soft = [float(r["plot_value"]) for r in done if float(r["param:materials.flexor.youngs"]) == 3e4]
    stiff = [float(r["plot_value"]) for r in done if float(r["param:materials.flexor.youngs"]) == 6e4]
    assert min(soft) > max(stiff)
    assert (out / "sweep.png").stat().st_size > 10000


def test_activation_curves_and_a_case_list_are_swept(tmp_path):
    path = write(tmp_path, {"activation.flexor.keys": [[[0.0, 0.0], [1.0, 0.3]], [[0.0, 0.0], [1.0, 0.9]]]})
    with open(path, "a") as f:
        f.write('[[cases]]\n"solver.method" = "fem"\n[[cases]]\n"solver.method" = "emu"\n')
    spec = load_sweep(path)
    assert len(spec["cases"]) == 4     # the grid times the list
    out = tmp_path / "out"
    emu.sweep(path, str(out), workers=2, progress=lambda *a: None)
    table = list(rows(out).values())
    assert len(table) == 4 and all(r["status"] == "done" for r in table)
    angle = {(r["param:activation.flexor.keys"], r["param:solver.method"]): float(r["plot_value"]) for r in table}
    weak, strong = "[[0.0, 0.0], [1.0, 0.3]]", "[[0.0, 0.0], [1.0, 0.9]]"
    for method in ("fem", "emu"):
        assert angle[strong, method] > angle[weak, method] + 1.0     # the curve reached the solve
    assert abs(angle[strong, "fem"] - angle[strong, "emu"]) < 1.0    # the method did too, same physics


def test_an_interrupted_sweep_resumes_without_rerunning_finished_cases(tmp_path):
    path = write(tmp_path, {"solver.alpha": [30.0, 100.0, 300.0, 1000.0]})
    out = tmp_path / "out"

    def stop_at_first_case(line):
        if line.startswith("  case "):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        emu.sweep(path, str(out), workers=2, progress=stop_at_first_case)
    first = rows(out)
    assert 1 <= len(first) < 4 and all(r["status"] == "done" for r in first.values())
    stamps = {c: os.path.getmtime(Path(r["output"]) / "log.json") for c, r in first.items()}
    lines = []
    emu.sweep(path, str(out), workers=2, progress=lines.append)
    assert f"{len(first)} done already, {4 - len(first)} to run" in lines[0]
    table = rows(out)
    assert len(table) == 4 and all(r["status"] == "done" for r in table.values())
    for c, t in stamps.items():   # the finished cases were not run again
        assert os.path.getmtime(Path(table[c]["output"]) / "log.json") == t


def test_cli_sweep_and_its_refusals(tmp_path):
    path = write(tmp_path, {"solver.alpha": [30.0, 300.0]})
    r = subprocess.run([sys.executable, "-m", "emu.app.cli", "sweep", str(path), "--out", str(tmp_path / "o"),
                        "--workers", "2"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "2/2 finished (2 done, 0 failed)" in r.stdout and (tmp_path / "o" / "results.csv").exists()
    cores = os.cpu_count()
    with pytest.raises(SweepError, match="oversubscribe"):
        emu.sweep(path, str(tmp_path / "p"), workers=cores, threads=2)
    bad = tmp_path / "bad.toml"
    bad.write_text('base = "arm.toml"\nplot = "speed"\n[grid]\n"solver.alpha" = [1.0]\n')
    with pytest.raises(SweepError, match="plot must be one of"):
        load_sweep(bad)
    assert case_id({"a": 1, "b": 2}) == case_id({"b": 2, "a": 1})
    # every case is checked before any runs: a misspelt key in one case, a
    # plotted bone that does not exist; nothing runs, each case is named
    typo = write(tmp_path, {"solver.accuracy": [0.01]}, extra="")
    with open(typo, "a") as f:
        f.write('[[cases]]\n"solver.method" = "fem"\n[[cases]]\n"solver.alfa" = 3.0\n')
    with pytest.raises(SweepError, match=r"1 of 2 case\(s\) would fail, nothing was run:\n  case .*solver.alfa.*"
                                         r"unknown key 'solver.alfa'"):
        emu.sweep(typo, str(tmp_path / "q"), workers=1)
    assert not any(p.name.startswith("case_") for p in (tmp_path / "q").iterdir())
    elbow = write(tmp_path, {"solver.alpha": [30.0]}).read_text().replace("angle:forearm", "angle:elbow")
    (tmp_path / "elbow.toml").write_text(elbow)
    with pytest.raises(SweepError, match="no movable or scripted bone 'elbow' \\(bones: forearm\\)"):
        emu.sweep(tmp_path / "elbow.toml", str(tmp_path / "r"), workers=1)


def test_without_dask_the_command_says_how_to_get_it(tmp_path):
    path = write(tmp_path, {"solver.alpha": [30.0]})
    code = ("import sys; sys.modules['dask'] = None; sys.modules['dask.distributed'] = None; "
            "from emu.app.cli import main; sys.exit(main(['sweep', sys.argv[1], '--out', sys.argv[2]]))")
    r = subprocess.run([sys.executable, "-c", code, str(path), str(tmp_path / "o")], capture_output=True, text=True)
    assert r.returncode == 2 and "pip install 'emu[sweep]'" in r.stderr
    # and every other command works without it
    code = "import sys; sys.modules['dask'] = None; import emu; print(emu.solve(emu.scenes.arm(1), method='fem').converged)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "True"
