"""``python -m emu``: the ``emu`` command (emu.app.cli), as the installed entry point runs it."""
import sys

from .app.cli import main

if __name__ == "__main__":
    sys.exit(main())
