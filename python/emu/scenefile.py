"""Scene files: the loader and its schema are emu.app.scenefile. This import
path stays because the README documents ``emu.scenefile.load_scene_file``."""
from .app.scenefile import SceneFileError, SceneSpec, load_scene_file

__all__ = ["SceneSpec", "load_scene_file", "SceneFileError"]
