"""emu: efficient muscle simulation in deformation space."""
from . import _core  # noqa: F401
