"""The ``emu`` command: its code is emu.app.cli. This module stays because
pyproject.toml's entry point names ``emu.cli:main`` (and ``python -m emu.cli``
keeps working)."""
import sys

from .app.cli import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
