"""A solve's load as the C++ core takes it (_core.LoadCase): per-muscle
activations, gravity, pin targets and the targets of scripted bones."""
from __future__ import annotations

import math
import warnings

import numpy as np

from .. import _core
from ..core.geometry import bbox_diagonal, tet_vertices
from ..model.lowering import declared_joint_rows, declared_joint_world
from ..core.poses import parse_pose
from .solution import Solution

__all__ = ["ActivationWarning", "activation_vector", "load_case", "start_array"]


class ActivationWarning(UserWarning):
    """An absolute activation that looks like a fraction of the muscle's
    maximum (normalized=True forgotten)."""


# An absolute activation in (0, 1] at most this fraction of the muscle's
# maximum is almost surely a fraction meant with normalized=True.
NORMALIZED_LOOKALIKE = 1e-3


def activation_vector(scene, activation=None, normalized: bool = False, warned: set | None = None) -> np.ndarray:
    """Per-muscle absolute activations (#muscles,) from a {muscle: value} dict
    (missing: 0; normalized: fractions of each muscle's maximum). warned: the
    muscles already warned about an absolute value that looks like a fraction
    (added to; None: warn every time)."""
    names = scene.muscles
    a = np.zeros(len(names))
    if activation is None:
        return a
    if not isinstance(activation, dict):
        raise TypeError("activation must be a dict {muscle name: value}")
    warned = set() if warned is None else warned
    for name, v in activation.items():
        if name not in names:
            raise ValueError(f"unknown muscle '{name}'; the scene's muscles are {names}")
        v = float(v)
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"activation of '{name}' must be finite and >= 0, got {v}")
        top = scene.parts[name].max_activation
        if normalized:
            if v > 1:
                raise ValueError(f"normalised activation of '{name}' must lie in [0, 1], got {v}")
            v *= top
        elif 0 < v <= 1 and v <= NORMALIZED_LOOKALIKE * top and name not in warned:
            warned.add(name)
            warnings.warn(ActivationWarning(
                f"activation {v:g} of '{name}' is absolute (a stress in the mesh's units; the muscle's "
                f"maximum is {top:g}), so it barely acts: for a fraction of the maximum pass "
                "normalized=True (scene files and --activation take fractions)"), stacklevel=5)
        a[names.index(name)] = v
    return a


def load_case(scene, activation=None, normalized=False, gravity=None, pin_positions=None, bone_poses=None,
              warned: set | None = None):
    """The core's LoadCase of a solve (Solver.solve's arguments of the same names)."""
    load = _core.LoadCase()
    load.activation = activation_vector(scene, activation, normalized, warned)
    g = scene.gravity if gravity is None else np.asarray(gravity, dtype=np.float64)
    if np.shape(g) != (3,) or not np.all(np.isfinite(g)):
        raise ValueError(f"gravity must be a finite 3-vector, got {g!r}")
    load.gravity = g
    ids, targets = scene.model_pins()
    if bone_poses:
        targets = _bone_targets(scene, bone_poses, ids, targets)
    if pin_positions is not None:
        pins = np.asarray(pin_positions, dtype=np.float64)
        if pins.shape != (len(scene.pinned), 3):
            raise ValueError(f"pin_positions must have shape ({len(scene.pinned)}, 3) (one row per "
                             f"scene.pinned vertex), got {pins.shape}")
        if not np.all(np.isfinite(pins)):
            raise ValueError("pin_positions contain NaN or inf")
        targets = targets.copy()
        targets[np.searchsorted(ids, scene.pinned)] = pins
    load.pin_positions = targets
    world = declared_joint_world(scene)
    if world and bone_poses:
        pts, _ = declared_joint_rows(scene)
        jt = pts.copy()
        for row, bone in world:
            if bone in bone_poses:
                R, t = parse_pose(bone, bone_poses[bone])
                jt[row] = R @ pts[row] + t
        load.joint_targets = jt
    return load


def set_inertia(load, scene, inertia) -> None:
    """load's inertia from (w, y): a time step's weight 1 / h_eff^2 and (n, 3)
    predicted positions (emu.solve.dynamics)."""
    try:
        w, y = inertia
        w = float(w)
    except (TypeError, ValueError):
        raise TypeError("inertia must be (weight, predicted positions): 1 / h^2 and an (n, 3) array") from None
    y = np.asarray(y, dtype=np.float64)
    if not (np.isfinite(w) and w >= 0):
        raise ValueError(f"the inertia weight must be finite and >= 0 (1 / h^2 of a time step), got {w!r}")
    if y.shape != (len(scene.points), 3) or not np.all(np.isfinite(y)):
        raise ValueError(f"the inertia's predicted positions must be a finite ({len(scene.points)}, 3) array, "
                         f"got shape {y.shape}")
    load.inertia_weight = w
    load.inertia_target = y


def _bone_targets(scene, bone_poses, ids, targets):
    """targets (the pinned vertices ids' positions) with the vertices of scripted
    bones moved: x = R X + t for each {bone: (R, t)}."""
    if not isinstance(bone_poses, dict):
        raise TypeError("bone_poses must be a dict {bone name: (R, t)} or {bone name: 4x4 matrix}")
    bones = {p.name: p for p in scene.parts.values() if p.kind == "bone"}
    poses = {}
    for name, pose in bone_poses.items():
        if name not in bones:
            raise ValueError(f"bone_poses: no bone named '{name}' (bones: {', '.join(bones) or 'none'})")
        if not bones[name].fixed:
            raise ValueError(f"bone_poses: bone '{name}' is moved by the muscles (fixed=False); only fixed "
                             "bones can be scripted")
        poses[name] = parse_pose(name, pose)

    def placed(name, X):  # where bone `name` puts rest points X
        if name not in poses:
            return X
        R, t = poses[name]
        return X @ R.T + t

    targets = targets.copy()
    for name in poses:
        verts = tet_vertices(scene.tets[bones[name].tets], len(scene.points))
        targets[np.searchsorted(ids, verts)] = placed(name, scene.points[verts])
    _check_joints_together(scene, bones, placed)
    return targets


def _check_joints_together(scene, bones, placed) -> None:
    """A vertex shared by two fixed bones (a joint) must land in the same place under both poses."""
    diag = bbox_diagonal(scene.points)
    for joint in scene.joints():
        a, b = joint.bones
        if joint.declared or not (bones[a].fixed and bones[b].fixed):
            continue  # a movable bone follows its joint by itself
        X = scene.points[joint.vertices]
        gap = np.linalg.norm(placed(a, X) - placed(b, X), axis=1)
        if gap.max() > 1e-9 * diag:
            v = joint.vertices[int(np.argmax(gap))]
            raise ValueError(f"bones '{a}' and '{b}' share vertex {v}, which their poses put "
                             f"{gap.max():.3g} apart; a joint must stay together "
                             "(rotate about the joint: the hinge axis or ball centre)")


def start_array(scene, method: str, initial):
    """A warm start as the core takes it: FEM (n, 3) positions, EMU (m, 3, 3)
    deformation gradients, from an array of that shape or a Solution of the same method."""
    if isinstance(initial, Solution):
        if initial.method != method:
            raise ValueError(f"cannot warm-start a {method} solve from a {initial.method} solution")
        initial = initial.F if method == "emu" else initial.positions
    a = np.asarray(initial, dtype=np.float64)
    if method == "fem":
        if a.shape != scene.points.shape:
            raise ValueError(f"initial positions must have shape {scene.points.shape}, got {a.shape}")
        return a
    m = len(scene.tets)
    if a.shape != (m, 3, 3):
        raise ValueError(f"initial deformation gradients must have shape ({m}, 3, 3), got {a.shape}")
    return a
