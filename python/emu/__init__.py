"""emu: efficient muscle simulation in deformation space (Modi et al. 2021).

    import emu
    scene = emu.Scene(points, tets)
    scene.add_muscle("belly", tets=idx, fibers=u)
    scene.pin(ids)
    sol = emu.solve(scene, activation={"belly": 5e4}, method="emu")

This module is the facade: it re-exports the public names and is imported by
nothing inside the package (every internal import is relative and goes to a
lower layer; tests/test_imports.py enforces it).
"""
from .blas_kernel import choose as _choose_blas_kernel

_choose_blas_kernel()   # before the C++ core loads OpenBLAS: its kernel is fixed then
from . import _core  # noqa: E402
from .checks import inverted_tets
from .geometry import bbox_diagonal, error_history, time_to_error, vertex_error
from .joints import Joint
from .parts import Part, lame
from .poses import pose_about, rotation
from .runtime import __version__, info
from .scene import MeshWarning, Scene
from .solve import AccuracyWarning, ActivationWarning, NeutralModeWarning, Solution, Solver, solve
from .options import AccuracyOptions, EmuOptions, FemOptions, NewtonOptions, StoppingOptions
from .bones import bone_angle, bone_motion, rigid_fit, signed_angle
from .contact import ContactWarning
from .app.sweep import sweep
from . import activation, anatomy, bones, contact, datasets, fibers, geometry, io, joints, lowering, meshes, options, poses, run, scenefile, scenes

__all__ = ["Scene", "Part", "Joint", "MeshWarning", "lame", "Solver", "Solution", "solve", "StoppingOptions",
           "AccuracyOptions", "NewtonOptions", "EmuOptions", "FemOptions", "rotation", "pose_about",
           "io", "meshes", "scenes", "datasets", "fibers", "info", "vertex_error", "error_history", "time_to_error", "bbox_diagonal", "inverted_tets", "bone_angle", "bone_motion", "rigid_fit",
           "signed_angle", "NeutralModeWarning", "AccuracyWarning", "ActivationWarning", "ContactWarning", "contact", "sweep", "__version__"]
