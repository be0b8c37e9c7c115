"""docs/layout.md, generated from the source tree: the Python package's layers
(one folder each, the order imports run in) and the C++ core's folders, each
module or unit with the first line of its own docstring or header comment.

    python tools/layout.py > docs/layout.md     # tests/test_layout.py keeps the page current

The layers and what each may import are defined here, once: tests/test_imports.py
checks every import against them.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "emu"
# the layer folders of python/emu, bottom first, and the layers each may import
LAYER_FOLDERS = ("core", "model", "io", "build", "solve", "app")
MAY_IMPORT = {
    "core": {"core"},
    "model": {"core", "model"},
    "io": {"core", "model", "io"},
    "build": {"core", "model", "io", "build"},
    "solve": {"core", "model", "solve"},
    "app": {"core", "model", "io", "build", "solve", "app"},
    "facade": {"core", "model", "io", "build", "solve", "app", "facade"},
}
# what each folder of cpp/emu holds (a folder without an entry, or an entry
# without a folder, stops the page from being written)
CPP_FOLDERS = {
    "energy": "one energy term per header, each value / gradient / Hessian (finite-difference tested)",
    "mesh": "tet geometry, fixed-pattern assembly, connectivity, orderings, harmonic fields",
    "linalg": "factorisations, our back-substitution, block inverses, modes, rotations, BLAS details",
    "contact": "energies of the positions evaluated outside the core (contact)",
    "model": "the flat per-tet model the solvers take, its unknowns and load cases",
    "solvers": "what both solvers share: options, the element term, the bone forest",
    "solvers/newton": "the Newton loop written once, and its parts",
    "solvers/emu": "EMU: the ACAP fit, its preconditioners and coarse space, bones on SO(3) and in joint coordinates",
    "solvers/fem": "FEM: Newton on positions, rigid bones in reduced joint coordinates",
}


def first_sentence(text: str | None) -> str:
    """The first sentence of a docstring or comment block's first paragraph, on one line."""
    para = []
    for line in (text or "").splitlines():
        line = line.strip().lstrip("/").strip()
        if line.startswith("#pragma"):
            continue
        if not line:
            if para:
                break
            continue
        para.append(line)
    text = " ".join(para)
    m = re.search(r"[.:](\s|$)", text)
    return text[:m.start() + 1].rstrip(":") if m else text


def python_layers() -> list:
    """[(folder, its docstring's first line, [(module, first line)])] in layer order."""
    out = []
    for folder in LAYER_FOLDERS:
        base = PACKAGE / folder
        doc = ast.get_docstring(ast.parse((base / "__init__.py").read_text()))
        mods = [(p.stem, first_sentence(ast.get_docstring(ast.parse(p.read_text()))))
                for p in sorted(base.glob("*.py")) if p.name != "__init__.py"]
        out.append((folder, first_sentence(doc), mods))
    return out


def header_comment(path: Path) -> str:
    """The first sentence of a C++ header's leading comment (after #pragma once)."""
    block = []
    for line in path.read_text().splitlines():
        s = line.strip()
        if s.startswith("//"):
            block.append(s)
        elif block or (s and not s.startswith("#")):
            break
    return first_sentence("\n".join(block))


def cpp_folders() -> list:
    """[(folder, what it holds, [(unit, first comment line)])] of cpp/emu."""
    base = ROOT / "cpp" / "emu"
    found = sorted(str(p.relative_to(base)) for p in base.rglob("*") if p.is_dir())
    if set(found) != set(CPP_FOLDERS):
        raise SystemExit(f"tools/layout.py: CPP_FOLDERS {sorted(CPP_FOLDERS)} and the folders {found} differ")
    out = []
    for folder in CPP_FOLDERS:
        units = [(p.stem, header_comment(p)) for p in sorted((base / folder).glob("*.h"))]
        out.append((folder, CPP_FOLDERS[folder], units))
    return out


def page() -> str:
    lines = ["# Source layout", "",
             "Generated from the source tree by `python tools/layout.py > docs/layout.md` (a test keeps it "
             "current): each module or unit with the first line of its own docstring or header comment.", "",
             "## Python: `python/emu`, one folder per layer", "",
             "Imports run one way, from the top layer down (tests/test_imports.py): a module imports its own "
             "layer and the layers listed beside it, never the facade (`emu/__init__.py`, the public names; "
             "`emu/__main__.py`, `python -m emu`).", ""]
    for folder, doc, mods in python_layers():
        below = ", ".join(f for f in LAYER_FOLDERS if f in MAY_IMPORT[folder] and f != folder) or "nothing"
        lines += [f"### `emu/{folder}`: {doc}", "", f"Imports: {below}.", ""]
        lines += [f"- `{m}`: {d}" for m, d in mods] + [""]
    lines += ["## C++: `cpp/emu`", "",
              "Bindings in `cpp/bindings` (one `bind_<topic>.cpp` per folder), tests in `cpp/tests` "
              "(ctest executables), micro-benchmarks in `bench/micro`.", ""]
    for folder, what, units in cpp_folders():
        lines += [f"### `cpp/emu/{folder}`: {what}", ""]
        lines += [f"- `{u}`: {d}" if d else f"- `{u}`" for u, d in units] + [""]
    lines += ["## The rest", "",
              "- `tests/`: pytest, one file per topic; `cpp/tests/`: the C++ tests",
              "- `bench/`: benchmark scripts that print tables (README.md has the results); "
              "`bench/studies/`: the measurements behind docs/DESIGN.md",
              "- `tools/`: this page's generator, unit sizes (`tools/unit_sizes.py`)",
              "- `docs/`: the user guide, METHOD.md (the method and model), DESIGN.md (decisions and "
              "measurements)", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.stdout.write(page())
