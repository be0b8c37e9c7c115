"""docs/layout.md is the page tools/layout.py writes from the source tree, so
that it cannot drift from the folders; the page lists every module and header
git tracks, each under its own folder (a file git ignores would be missing
from a clone: the page would still name it from a working tree, this test not);
and no Python function is over tools/unit_sizes.py's limit."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from conftest import repo_tool

ROOT = Path(__file__).resolve().parents[1]


def tracked(*paths) -> list:
    try:
        out = subprocess.run(["git", "ls-files", *paths], cwd=ROOT, capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files cannot be listed")
    return [Path(p) for p in out.stdout.split()]


def page_sections(page: str) -> dict:
    """{folder heading path: set of unit names listed under it}."""
    out, current = {}, None
    for line in page.splitlines():
        if m := re.match(r"### `([^`]+)`", line):
            current = out.setdefault(m.group(1), set())
        elif current is not None and (m := re.match(r"- `([^`]+)`", line)):
            current.add(m.group(1))
    return out


def test_the_layout_page_is_current():
    assert (ROOT / "docs" / "layout.md").read_text() == repo_tool("layout").page(), \
        "docs/layout.md is stale: run python tools/layout.py > docs/layout.md"


def test_the_page_lists_every_tracked_module_and_header_under_its_folder():
    sections = page_sections((ROOT / "docs" / "layout.md").read_text())
    layers = repo_tool("layout").LAYER_FOLDERS
    for p in tracked("python/emu"):
        rel = p.relative_to("python/emu")
        if p.suffix == ".py" and len(rel.parts) == 2 and rel.parts[0] in layers and p.name != "__init__.py":
            assert p.stem in sections.get(f"emu/{rel.parts[0]}", set()), f"{p} is not on the page under its folder"
    for p in tracked("cpp/emu"):
        if p.suffix == ".h":
            assert p.stem in sections.get(str(p.parent), set()), f"{p} is not on the page under its folder"
    for folder in layers:   # a layer's __init__ ignored by git would be missing from every clone and wheel
        assert Path(f"python/emu/{folder}/__init__.py") in tracked(f"python/emu/{folder}/__init__.py")


def test_no_python_function_is_over_the_limit():
    sizes = repo_tool("unit_sizes")
    over = [f"{where}: {name} ({n} lines)" for kind, where, name, n in sizes.units()
            if kind == "function" and where.suffix == ".py" and n > sizes.LIMITS["function"]]
    assert not over, "split these functions (tools/unit_sizes.py):\n" + "\n".join(over)
