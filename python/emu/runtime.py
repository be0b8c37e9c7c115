"""What the C++ core runs on (BLAS, threads) and the package version: every
timing should say what it ran on."""
from __future__ import annotations

from . import _core

__all__ = ["__version__", "info", "set_threads"]

__version__ = "0.1.0"


def info() -> dict:
    """Which BLAS and how many threads the C++ core runs on."""
    d = dict(_core.blas_info())
    d["version"] = __version__
    return d


def set_threads(threads: int) -> None:
    """Set the OpenMP and OpenBLAS threads of the C++ core (threads >= 1)."""
    if int(threads) < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    _core.set_threads(int(threads))
