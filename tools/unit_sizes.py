"""The longest functions and classes of the code base, in lines (issue 44's
measure: no Python function over about 60 lines, no class over about 250).

    python tools/unit_sizes.py            # the units over the limits, longest first
    python tools/unit_sizes.py --all 20   # the 20 longest of each kind
    python tools/unit_sizes.py --check    # exit 1 where a unit is over its limit

Python units come from ``ast`` (a function's lines from its ``def`` to its
last statement, docstring included, decorators not). C++ units are read from
the text: a class or struct body from its ``{`` to the matching ``}``, a
function body likewise (a definition: a name and a parameter list followed by
``{`` at namespace or class level); comments and string literals are skipped
when braces are matched.
"""
from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMITS = {"function": 60, "class": 250}


def python_units(path: Path):
    """(kind, qualified name, lines) of every function and class in a Python file."""
    tree = ast.parse(path.read_text())

    def walk(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                kind = "class" if isinstance(child, ast.ClassDef) else "function"
                name = f"{prefix}{child.name}"
                yield kind, name, child.end_lineno - child.lineno + 1
                yield from walk(child, name + ".")
    yield from walk(tree, "")


_STRIP = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\])*"|\'(?:\\.|[^\'\\])*\'', re.S)
_CLASS = re.compile(r"\b(class|struct)\s+(\w+(?:::\w+)*)[^;{()]*$")
_FUNC = re.compile(r"([\w:~<>]+)\s*\([^;{}]*\)\s*(?:const\s*)?(?:noexcept\s*)?(?:override\s*)?(?:->\s*[\w:<>]+\s*)?"
                   r"(?::[^;{}]*)?$")
_NOT_FUNC = {"if", "for", "while", "switch", "catch", "return", "sizeof"}


def cpp_units(path: Path):
    """(kind, name, lines) of C++ classes/structs and function bodies (lambdas and
    control blocks inside a body belong to it)."""
    text = _STRIP.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), path.read_text())
    stack = []   # (kind or None, name, start line) per open brace
    line, last = 1, 0
    for i, ch in enumerate(text):
        if ch == "\n":
            line += 1
        elif ch == "{":
            head = text[last:i]
            inside_function = any(k == "function" for k, _, _ in stack)
            kind = name = None
            if not inside_function:
                tail = head[head.rfind(";") + 1:].strip() if ";" in head else head.strip()
                tail = tail.split("}")[-1].strip()
                if (m := _CLASS.search(tail)) and "(" not in tail:
                    kind, name = "class", m.group(2)
                elif (m := _FUNC.search(" ".join(tail.split()))) and m.group(1).split("::")[-1] not in _NOT_FUNC:
                    kind, name = "function", m.group(1)
            stack.append((kind, name, line))
            last = i + 1
        elif ch == "}":
            if stack:
                kind, name, start = stack.pop()
                if kind is not None:
                    yield kind, name, line - start + 1
            last = i + 1
        elif ch == ";":
            last = i + 1


def units():
    """(kind, where, name, lines) of every unit in python/emu, cpp/emu, bench and tools."""
    for p in sorted((ROOT / "python" / "emu").rglob("*.py")) + sorted((ROOT / "bench").rglob("*.py")) + \
            sorted((ROOT / "tools").rglob("*.py")):
        for kind, name, n in python_units(p):
            yield kind, p.relative_to(ROOT), name, n
    for p in sorted((ROOT / "cpp" / "emu").rglob("*.[ch]*")):
        if p.suffix in (".h", ".cpp"):
            for kind, name, n in cpp_units(p):
                yield kind, p.relative_to(ROOT), name, n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--all", type=int, default=0, metavar="N", help="the N longest of each kind")
    ap.add_argument("--check", action="store_true", help="exit 1 where a unit is over its limit")
    a = ap.parse_args(argv)
    found = sorted(units(), key=lambda u: -u[3])
    over = [u for u in found if u[3] > LIMITS[u[0]]]
    for kind in ("function", "class"):
        rows = [u for u in found if u[0] == kind]
        shown = rows[:a.all] if a.all else [u for u in rows if u[3] > LIMITS[kind]]
        print(f"{kind}{'es' if kind == 'class' else 's'} over {LIMITS[kind]} lines: {sum(u[3] > LIMITS[kind] for u in rows)} of {len(rows)}")
        for _, where, name, n in shown:
            print(f"  {n:5d}  {where}: {name}")
    return 1 if a.check and over else 0


if __name__ == "__main__":
    sys.exit(main())
