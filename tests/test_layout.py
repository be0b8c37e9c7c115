"""docs/layout.md is the page tools/layout.py writes from the source tree, so
that it cannot drift from the folders (a moved, added or removed module or
header changes the page)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def layout_tool():
    spec = importlib.util.spec_from_file_location("layout_tool", ROOT / "tools" / "layout.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_layout_page_is_current():
    page = layout_tool().page()
    assert (ROOT / "docs" / "layout.md").read_text() == page, \
        "docs/layout.md is stale: run python tools/layout.py > docs/layout.md"


def test_the_page_names_every_module_and_header():
    tool = layout_tool()
    page = tool.page()
    for p in (ROOT / "python" / "emu").rglob("*.py"):
        if p.parent.name in tool.LAYER_FOLDERS and p.name != "__init__.py":
            assert f"- `{p.stem}`" in page, p
    for p in (ROOT / "cpp" / "emu").rglob("*.h"):
        assert f"- `{p.stem}`" in page, p
