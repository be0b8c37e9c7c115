"""Every example scene file loads from a clone (the research scenes through
emu.datasets, here from the shared offline copy) and its first frames solve."""
from __future__ import annotations

from pathlib import Path

import pytest

from emu.app.run import run_scene
from emu.app.scenefile import load_scene_file
from conftest import shared_raw

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.toml"))


def test_there_are_examples():
    assert len(EXAMPLES) >= 7


def _needs_research_data(path):
    """The authors' scenes come from the shared copy; arm26's files are in tests/data."""
    return "dataset" in path.read_text() and 'dataset = "arm26"' not in path.read_text()


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_loads_and_its_first_frames_solve(path, tmp_path):
    assert "shared/data" not in path.read_text(), "examples must not read files outside the project"
    if _needs_research_data(path):
        shared_raw()
    spec = load_scene_file(path)
    assert spec.frames >= 2 and spec.curves
    spec.frames = 2   # the rest pose and the first activated frame
    log = run_scene(spec, str(tmp_path), progress=lambda *a, **k: None)
    assert [f["converged"] for f in log["frames"]] == [True, True], [f["status"] for f in log["frames"]]
    assert (tmp_path / "series.pvd").exists()


def test_the_example_sweep_file_loads_and_every_case_builds():
    from emu.app.sweep import check_cases, load_sweep

    [path] = (Path(__file__).resolve().parents[1] / "examples" / "sweeps").glob("*.toml")
    spec = load_sweep(path)
    assert len(spec["cases"]) == 8 and spec["plot"] == "angle:forearm"
    check_cases(spec["base"], spec["cases"], spec["plot"])   # raises naming a case that would fail
