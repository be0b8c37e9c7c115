"""Imports inside the package run one way.

Every module under python/emu is parsed with ``ast`` (imports inside functions
included): none may import ``emu`` by its absolute name (relative imports
only), each belongs to a layer, the folder it lives in (emu/core, emu/model,
emu/io, emu/build, emu/solve, emu/app), and imports only from the layers below
it (or its own), nothing imports the facade (``emu/__init__`` and
``emu.__main__``), and the module graph has no cycle. docs/layout.md draws the
same layers (tools/layout.py writes it; test_layout.py keeps it current).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest
from conftest import repo_tool

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "emu"

# The layers are the package's folders (emu/core, emu/model, ...), defined with
# what each may import in tools/layout.py (which draws docs/layout.md from them);
# a module's layer is the folder it lives in. The facade is emu/__init__.py and
# emu/__main__.py; the C++ core, emu._core, is the bottom.
_layout = repo_tool("layout")
LAYER_FOLDERS, MAY_IMPORT = _layout.LAYER_FOLDERS, _layout.MAY_IMPORT


def layer_of(module: str) -> str | None:
    """The layer of a module by its folder: emu.<folder>[.<module>]; None for a
    module that lives in no layer folder."""
    parts = module.split(".")
    if module in ("emu", "emu.__main__"):
        return "facade"
    if module == "emu._core":
        return "core"
    return parts[1] if len(parts) >= 2 and parts[1] in LAYER_FOLDERS else None


def module_name(path: Path) -> tuple[str, bool]:
    """(dotted module name, is a package __init__) of a file under PACKAGE."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), True
    return ".".join(parts), False


def package_modules() -> dict:
    """{module name: (path, is_package)} of every .py file in the package."""
    return {module_name(p)[0]: (p, module_name(p)[1]) for p in sorted(PACKAGE.rglob("*.py"))}


def imports_of(source: str, name: str, is_package: bool, known: set) -> tuple[list, list]:
    """(absolute self-imports as (line, text), internal edges as (line, target module))
    of one module's source, imports inside functions included."""
    absolute, edges = [], []
    here = name if is_package else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "emu" or a.name.startswith("emu."):
                    absolute.append((node.lineno, f"import {a.name}"))
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if node.module == "emu" or (node.module or "").startswith("emu."):
                    absolute.append((node.lineno, f"from {node.module} import ..."))
                continue
            base = here.split(".")
            if node.level > 1:
                base = base[:-(node.level - 1)]
            target = ".".join(base + ([node.module] if node.module else []))
            for a in node.names:   # "from . import scenes" imports the module emu.scenes
                sub = f"{target}.{a.name}"
                edges.append((node.lineno, sub if sub in known else target))
    return absolute, edges


def graph() -> tuple[dict, dict]:
    """({module: [(line, target)]}, {module: [(line, absolute import)]}) of the package."""
    mods = package_modules()
    known = set(mods) | {"emu._core"}
    edges, absolute = {}, {}
    for name, (path, is_pkg) in mods.items():
        absolute[name], edges[name] = imports_of(path.read_text(), name, is_pkg, known)
    return edges, absolute


def layering_errors(edges: dict) -> list:
    errors = []
    for name, targets in edges.items():
        here = layer_of(name)
        if here is None:
            errors.append(f"{name} is in no layer: move it into one of the folders emu/{{{', '.join(LAYER_FOLDERS)}}}")
            continue
        for line, target in targets:
            there = layer_of(target)
            if there is None:
                errors.append(f"{name}:{line} imports {target}, which is in no layer")
            elif there == "facade" and here != "facade":
                errors.append(f"{name}:{line} imports the facade module {target}; import the module that "
                              "defines the name")
            elif there not in MAY_IMPORT[here]:
                errors.append(f"{name}:{line} ({here} layer) imports {target} ({there} layer), a higher layer")
    return errors


def cycles(edges: dict) -> list:
    """Import cycles of the module graph, each as a list of modules."""
    adj = {n: sorted({t for _, t in ts if t in edges and t != n}) for n, ts in edges.items()}
    found, state, stack = [], {}, []

    def visit(n):
        state[n] = "open"
        stack.append(n)
        for t in adj[n]:
            if state.get(t) == "open":
                found.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[n] = "done"
    for n in sorted(adj):
        if n not in state:
            visit(n)
    return found


def test_no_module_imports_emu_by_its_absolute_name():
    _, absolute = graph()
    bad = [f"{name}:{line}: {text}" for name, found in absolute.items() for line, text in found]
    assert not bad, "inside the package import relatively (from .x import y):\n" + "\n".join(bad)


def test_every_module_imports_only_lower_layers():
    edges, _ = graph()
    errors = layering_errors(edges)
    assert not errors, "\n".join(errors)


def test_the_import_graph_has_no_cycle():
    edges, _ = graph()
    assert not cycles(edges)


def test_every_layer_folder_exists_and_says_what_it_holds():
    for folder in LAYER_FOLDERS:
        init = PACKAGE / folder / "__init__.py"
        assert init.is_file() and ast.get_docstring(ast.parse(init.read_text())), f"emu/{folder} needs a docstring"


# ------------------------------------------------------------- the checker can fail
@pytest.mark.parametrize("source,name,expect", [
    ("def f():\n    import emu\n", "emu.scene", "import emu"),
    ("from emu.io import read\n", "emu.app.run", "from emu.io import ..."),
    ("import emu.solve as s\n", "emu.bones", "import emu.solve"),
])
def test_checker_flags_absolute_imports(source, name, expect):
    absolute, _ = imports_of(source, name, False, set())
    assert [text for _, text in absolute] == [expect]


def test_checker_flags_an_upward_import_and_a_cycle():
    known = {"emu.app.run", "emu.__main__", "emu.io.mesh", "emu.io"}
    _, up = imports_of("def f():\n    from ..app.run import run_scene\n", "emu.io.vtk", False, known)
    assert up == [(2, "emu.app.run")]
    errors = layering_errors({"emu.io.vtk": up})
    assert len(errors) == 1 and "a higher layer" in errors[0]
    _, facade = imports_of("from .. import __main__\n", "emu.app.demo", False, known)
    assert facade == [(1, "emu.__main__")] and "facade" in layering_errors({"emu.app.demo": facade})[0]
    _, pkg = imports_of("from .. import _core\nfrom .mesh import read\n", "emu.io", True, known | {"emu._core"})
    assert pkg == [(1, "emu._core"), (2, "emu.io.mesh")]
    assert cycles({"emu.a": [(1, "emu.b")], "emu.b": [(3, "emu.a")]}) == [["emu.a", "emu.b", "emu.a"]]
    assert "in no layer" in layering_errors({"emu.stray": []})[0]   # a module outside the layer folders


def reachable(edges: dict, start: str) -> set:
    """Every module ``start`` imports, directly or through others (importing a
    module runs its packages' __init__ too)."""
    seen, todo = set(), [start]
    while todo:
        for _, t in edges.get(todo.pop(), []):
            parts = t.split(".")
            for k in range(2, len(parts) + 1):
                m = ".".join(parts[:k])
                if m not in seen:
                    seen.add(m)
                    todo.append(m)
    return seen


@pytest.mark.parametrize("loader", ["emu.app.scenefile", "emu.io", "emu.io.mesh", "emu.io.vtk", "emu.build.scenes"])
def test_file_loaders_do_not_import_the_solver(loader):
    """Reading a scene (a scene file, a mesh) needs no solver: poses live in
    emu.core.poses, the model lowering in emu.model.lowering, the options table and Frame
    in modules of emu.solve that do not load the solver)."""
    edges, _ = graph()
    assert "emu.solve.solver" not in reachable(edges, loader)
