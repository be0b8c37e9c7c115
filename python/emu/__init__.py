"""emu: efficient muscle simulation in deformation space (Modi et al. 2021).

    import emu
    scene = emu.Scene(points, tets)
    scene.add_muscle("belly", tets=idx, fibers=u)
    scene.pin(ids)
    sol = emu.solve(scene, activation={"belly": 5e4}, method="emu")

This module is the facade: it re-exports the public names (scene files:
emu.load_scene_file, emu.run_scene; ``python -m emu`` is the ``emu`` command)
and is imported by nothing inside the package (every internal import is relative and goes to a
lower layer; tests/test_imports.py enforces it).
"""
from .core.blas_kernel import choose as _choose_blas_kernel

_choose_blas_kernel()   # before the C++ core loads OpenBLAS: its kernel is fixed then
from . import _core  # noqa: E402
from .core.checks import inverted_tets
from .core.geometry import bbox_diagonal, error_history, time_to_error, vertex_error
from .model.joints import Joint
from .model.parts import Part, lame
from .core.poses import pose_about, rotation
from .core.runtime import __version__, info
from .model.scene import MeshWarning, Scene
from .solve.accuracy import AccuracyWarning
from .solve.load import ActivationWarning
from .solve.solution import Solution
from .solve.solver import NeutralModeWarning, Solver, solve
from .solve.options import AccuracyOptions, EmuOptions, FemOptions, NewtonOptions, StoppingOptions
from .model.bones import bone_angle, bone_motion, rigid_fit, signed_angle
from .model.contact import ContactWarning
from .solve.frames import Frame, solve_frames
from .solve.dynamics import Dynamics, MotionState, vertex_masses
from .app.sweep import sweep
from .app.run import run_scene
from .app.scenefile import SceneFileError, load_scene_file
from . import io
from .core import activation, checks, fibers, geometry, poses, runtime
from .model import bones, contact, joints, lowering
from .build import anatomy, arm26, author, datasets, procedural, scenes, shapes
from .solve import options

__all__ = ["Scene", "Part", "Joint", "MeshWarning", "lame", "Solver", "Solution", "solve", "StoppingOptions",
           "AccuracyOptions", "NewtonOptions", "EmuOptions", "FemOptions", "rotation", "pose_about",
           "io", "procedural", "scenes", "shapes", "anatomy", "author", "arm26", "datasets", "fibers", "info", "vertex_error", "error_history", "time_to_error", "bbox_diagonal", "inverted_tets", "bone_angle", "bone_motion", "rigid_fit",
           "signed_angle", "NeutralModeWarning", "AccuracyWarning", "ActivationWarning", "ContactWarning", "contact", "sweep",
           "run_scene", "load_scene_file", "SceneFileError", "Frame", "solve_frames", "Dynamics", "MotionState", "vertex_masses", "__version__",
           "activation", "checks", "geometry", "poses", "runtime", "bones", "joints", "lowering", "options"]
