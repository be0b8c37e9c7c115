"""``python -m emu.cli``: the ``emu`` command, whose code is emu.app.cli (the
installed ``emu`` entry point names emu.app.cli:main directly)."""
import sys

from .app.cli import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
