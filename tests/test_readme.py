"""The README's tour runs as written: its Python block, and the scene-file
keys and command-line options it shows exist."""
import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_the_python_tour_runs(tmp_path, monkeypatch):
    block = re.search(r"```python\n(.*?)```", README, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(block, "README.md", "exec"), namespace)
    assert namespace["prev"].converged and os.path.getsize(tmp_path / "frame.vtu") > 0


def test_the_scene_file_in_the_tour_loads(tmp_path):
    from emu import load_scene_file

    block = re.search(r"```toml\n(\[mesh.upper_limb\].*?)```", README, re.S).group(1)
    (tmp_path / "tour.toml").write_text(block)
    spec = load_scene_file(tmp_path / "tour.toml")
    assert spec.frames == 25 and "biceps" in spec.curves


def test_the_commands_in_the_tour_exist():
    from emu.app.cli import main
    import pytest

    for line in re.search(r"```\nemu run (.*?)```", README, re.S).group(0).splitlines()[1:-1]:
        command = line.split()[1]
        with pytest.raises(SystemExit) as e:
            main([command, "--help"])
        assert e.value.code == 0, line
        for option in re.findall(r"(--[a-z-]+)", line.split("#")[0]):
            assert option in _help(command), (command, option)


def _help(command) -> str:
    import contextlib
    import io

    from emu.app.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            main([command, "--help"])
        except SystemExit:
            pass
    return out.getvalue()


def test_the_getting_started_page_runs(tmp_path, monkeypatch):
    """docs/getting-started.md: its Python blocks run in order, as written."""
    page = (ROOT / "docs" / "getting-started.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", page, re.S)
    assert len(blocks) == 2
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for block in blocks:
        exec(compile(block, "getting-started.md", "exec"), namespace)
    assert namespace["sol"].converged and os.path.getsize(tmp_path / "flexed.vtu") > 0
    assert namespace["fem"].settings["rtol_grad"] == 1e-8 == namespace["emu_solver"].settings["rtol_grad"]
    assert namespace["emu_solver"].settings["step"] == "lbfgs"
