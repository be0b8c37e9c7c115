"""Running a scene over its frames: the code is emu.app.run. This import path
stays because the README documents ``emu.run.run_scene``."""
from .app.run import run_scene

__all__ = ["run_scene"]
