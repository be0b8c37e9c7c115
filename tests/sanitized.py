"""Run pytest on the emu package with the _core extension of the sanitize
build (CMakePresets.json "sanitize": ASan + UBSan) in place of the installed
one. Used by ``bash run.sh sanitize``, which preloads the sanitizer runtimes:

    python tests/sanitized.py BUILD_DIR [pytest arguments]

The package's Python files are linked into BUILD_DIR/python/emu beside the
sanitized _core, and that copy is imported first (an editable install's
import hook is taken out of the way)."""
from __future__ import annotations

import glob
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def sanitized_package(build: Path) -> Path:
    """BUILD_DIR/python with emu/ = the sources (symlinks) + the sanitized _core."""
    modules = glob.glob(str(build / "_core*.so"))
    if not modules:
        sys.exit(f"no _core*.so in {build}: build the sanitize preset first (bash run.sh sanitize)")
    dest = build / "python" / "emu"
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(ROOT / "python" / "emu", dest, symlinks=True,
                    copy_function=lambda src, dst: os.symlink(os.path.abspath(src), dst),
                    ignore=shutil.ignore_patterns("_core*.so", "__pycache__"))
    os.symlink(os.path.abspath(modules[0]), dest / os.path.basename(modules[0]))
    return dest.parent


def main(argv):
    build, args = Path(argv[0]).resolve(), argv[1:]
    path = str(sanitized_package(build))
    sys.path.insert(0, path)
    os.environ["PYTHONPATH"] = os.pathsep.join([path, os.environ.get("PYTHONPATH", "")])  # for subprocesses
    sys.meta_path[:] = [f for f in sys.meta_path if "ScikitBuild" not in type(f).__name__]
    import emu
    if not emu.__file__.startswith(path):
        sys.exit(f"imported {emu.__file__}, not the sanitized copy in {path}")
    import pytest
    return pytest.main(["-p", "no:cacheprovider", *args])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
