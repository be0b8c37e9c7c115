"""Imports inside the package run one way.

Every module under python/emu is parsed with ``ast`` (imports inside functions
included): none may import ``emu`` by its absolute name (relative imports
only), each belongs to a layer and imports only from the layers below it (or
its own), nothing imports the facade (``emu/__init__`` and ``emu.__main__``), and the module graph has no
cycle. A new module must be given a layer here.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "emu"

# layer -> modules (names relative to emu; "" is the package itself)
LAYERS = {
    # numerics and data with no notion of a scene
    "core": {"_core", "blas_kernel", "geometry", "checks", "activation", "poses", "meshes", "fibers", "runtime", "shapes"},
    # the scene, its parts and joints, the lowering to the C++ model, built-in scenes
    "model": {"parts", "joints", "contact", "scene", "lowering", "scenes"},
    # solving a scene and measuring a solution
    "solve": {"solve", "solve.accuracy", "solve.advice", "solve.estimate", "solve.load", "solve.options",
              "solve.solution", "solve.solver", "solve.frames", "bones"},
    # files in and out (never the solver)
    "io": {"io", "io.mesh", "io.vtk", "io.obj", "io.plots", "io.usd", "datasets", "author", "anatomy", "arm26"},
    # the application: command line, scene files, runs, the demo
    "app": {"app", "app.cli", "app.run", "app.demo", "app.scenefile", "app.sweep"},
    # the public facade and the import paths the README and pyproject.toml name
    "facade": {"", "__main__"},
}
MAY_IMPORT = {
    "core": {"core"},
    "model": {"core", "model"},
    "solve": {"core", "model", "solve"},
    "io": {"core", "model", "io"},
    "app": {"core", "model", "solve", "io", "app"},
    "facade": {"core", "model", "solve", "io", "app", "facade"},
}
LAYER_OF = {f"emu.{m}" if m else "emu": layer for layer, mods in LAYERS.items() for m in mods}


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
        if name not in LAYER_OF:
            errors.append(f"{name} is in no layer: add it to LAYERS in tests/test_imports.py")
            continue
        for line, target in targets:
            if target not in LAYER_OF:
                errors.append(f"{name}:{line} imports {target}, which is in no layer")
            elif LAYER_OF[target] == "facade" and LAYER_OF[name] != "facade":
                errors.append(f"{name}:{line} imports the facade module {target}; import the module that "
                              "defines the name")
            elif LAYER_OF[target] not in MAY_IMPORT[LAYER_OF[name]]:
                errors.append(f"{name}:{line} ({LAYER_OF[name]} layer) imports {target} ({LAYER_OF[target]} "
                              "layer), a higher layer")
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


def test_every_layer_names_existing_modules():
    mods = set(package_modules()) | {"emu._core"}
    missing = sorted(set(LAYER_OF) - mods)
    assert not missing, f"LAYERS names modules that do not exist: {missing}"


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
    known = set(LAYER_OF)
    _, up = imports_of("def f():\n    from ..app.run import run_scene\n", "emu.io.vtk", False, known)
    assert up == [(2, "emu.app.run")]
    errors = layering_errors({"emu.io.vtk": up})
    assert len(errors) == 1 and "a higher layer" in errors[0]
    _, facade = imports_of("from .. import __main__\n", "emu.app.demo", False, known)
    assert facade == [(1, "emu.__main__")] and "facade" in layering_errors({"emu.app.demo": facade})[0]
    _, pkg = imports_of("from .. import _core\nfrom .mesh import read\n", "emu.io", True, known | {"emu._core"})
    assert pkg == [(1, "emu._core"), (2, "emu.io.mesh")]
    assert cycles({"emu.a": [(1, "emu.b")], "emu.b": [(3, "emu.a")]}) == [["emu.a", "emu.b", "emu.a"]]


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


@pytest.mark.parametrize("loader", ["emu.app.scenefile", "emu.io", "emu.io.mesh", "emu.io.vtk", "emu.scenes"])
def test_file_loaders_do_not_import_the_solver(loader):
    """Reading a scene (a scene file, a mesh) needs no solver: poses live in
    emu.poses, the model lowering in emu.lowering, the options table and Frame
    in modules of emu.solve that do not load the solver)."""
    edges, _ = graph()
    assert "emu.solve.solver" not in reachable(edges, loader)
