"""emu: efficient muscle simulation in deformation space (Modi et al. 2021).

    import emu
    scene = emu.Scene(points, tets)
    scene.add_muscle("belly", tets=idx, fibers=u)
    scene.pin(ids)
    sol = emu.solve(scene, activation={"belly": 5e4}, method="emu")
"""
from . import _core
from .scene import Scene, Part, MeshWarning, lame
from .solve import NeutralModeWarning, Solver, Solution, pose_about, rotation, solve
from .bones import bone_motion, rigid_fit, signed_angle
from . import activation, bones, fibers, io, meshes, run, scenefile, scenes

__version__ = "0.1.0"

__all__ = ["Scene", "Part", "MeshWarning", "lame", "Solver", "Solution", "solve", "rotation", "pose_about", "io", "meshes", "fibers", "info",
           "vertex_error", "bone_motion", "rigid_fit", "signed_angle", "NeutralModeWarning"]


def info() -> dict:
    """Which BLAS and how many threads the C++ core runs on."""
    d = dict(_core.blas_info())
    d["version"] = __version__
    return d


def vertex_error(a, b, points=None) -> float:
    """Largest vertex distance between two (n, 3) position arrays (or Solutions),
    relative to the bounding-box diagonal of ``points`` (default: of ``b``)."""
    import numpy as np

    pa = np.asarray(getattr(a, "positions", a))
    pb = np.asarray(getattr(b, "positions", b))
    if pa.shape != pb.shape:
        raise ValueError(f"position arrays differ in shape: {pa.shape} vs {pb.shape}")
    ref = pb if points is None else np.asarray(points)
    diag = float(np.linalg.norm(ref.max(0) - ref.min(0)))
    return float(np.linalg.norm(pa - pb, axis=1).max() / diag)
