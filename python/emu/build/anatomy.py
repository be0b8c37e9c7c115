"""Built-in anatomy from smooth shapes: bones as capsules (shafts with
rounded ends), muscle bellies as spindles tapering into their attachments,
meshed by `emu.author` (fTetWild) and cached after the first build.

    arm(resolution)   humerus (fixed) and forearm on the elbow hinge, flexor
                      and extensor; the box arm's layout (emu.scenes.arm): the
                      humerus up (+y), the forearm along +x, the hinge about +z
                      through the origin (flexion: a positive turn)
    leg(resolution)   femur (fixed) and tibia on the knee hinge, hamstring
                      behind (flexes the knee) and quadriceps in front
                      (straightens it); the knee bent 15 degrees at rest
    neck(resolution)  torso (fixed) and head on a ball joint, four muscles
                      (left_back, right_back, left_front, right_front)
    upper_limb(resolution)  the arm on a shoulder: scapula (fixed), humerus on
                      the shoulder's ball joint (a passive spring), forearm on
                      the elbow hinge; biceps and triceps span both joints,
                      the deltoid the shoulder (a chain of two movable bones)

Sizes are in metres (an adult's arm at about half scale, as the box arm).
``resolution`` sets the surfaces' tessellation, the mesher's envelope and a
target of ANATOMY_TETS x resolution^2 tets; measured: about 2k tets at 1, 4k
at 2 and 7k at 3 (the arm; the leg and the neck a little more), meshed in
3, 10 and 20 s. fTetWild's meshes differ slightly from run to run (6.7k or
6.9k tets for the same arm), so resolutions 1 to 3 ship with the package
(emu/build/data/anatomy: every machine solves the same mesh, and nothing is meshed
on first use); other resolutions are built once per machine and cached in
EMU_CACHE_DIR (default: the user's cache folder, emu/anatomy). Both are keyed
by the shapes and the resolution: a changed shape is meshed afresh.
"""
from __future__ import annotations

import hashlib
import json
import os

import numpy as np

from .author import JointSpec, PartSpec, PartsFile, author
from ..model.scene import Scene
from .shapes import capsule, spindle

__all__ = ["arm", "leg", "neck", "upper_limb", "cache_dir", "ANATOMY_TETS", "SHOULDER_STIFFNESS"]

# Tets per resolution^2 (fTetWild's count only approximates the target).
ANATOMY_TETS = 700
# upper_limb: the shoulder's passive stiffness (N m / rad)
SHOULDER_STIFFNESS = 0.05
# Bump when a shape changes: the cache key holds it.
_VERSION = 1
# The meshes that ship with the package (_rebuild_shipped() remeshes them).
SHIPPED_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "anatomy")
SHIPPED_RESOLUTIONS = (1, 2, 3)


def cache_dir() -> str:
    """Where built meshes are kept: EMU_CACHE_DIR, else $XDG_CACHE_HOME/emu/anatomy (~/.cache)."""
    d = os.environ.get("EMU_CACHE_DIR")
    if d:
        return os.path.join(d, "anatomy")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "emu", "anatomy")


# The surfaces' tessellation and the mesher's envelope follow the resolution:
# fTetWild refines to the input triangles within its envelope, so fine surfaces
# or a tight envelope set a floor under the tet count whatever the target.
def _rings(resolution: int) -> int:
    return 6 + 4 * resolution


def _epsilon(resolution: int) -> float:
    return 3e-3 / resolution


def _arm_parts(rings: int) -> tuple:
    ring = dict(rings=rings, segments=rings)
    # the forearm runs behind the hinge (its olecranon, x < 0) for the extensor's lever
    parts = [
        PartSpec("humerus", capsule([0, 0.016, 0], [0, 0.13, 0], 0.008, **ring), "bone"),
        PartSpec("forearm", capsule([-0.024, 0, 0], [0.125, 0, 0], 0.007, **ring), "bone", fixed=False),
        PartSpec("flexor", spindle([0.004, 0.105, 0], [0.04, 0.002, 0], 0.012, end_radius=0.003, **ring),
                 "muscle"),
        PartSpec("extensor", spindle([-0.005, 0.115, 0], [-0.019, 0.0, 0], 0.01, end_radius=0.003, **ring),
                 "muscle"),
    ]
    joints = [JointSpec(("humerus", "forearm"), np.array([0.0, 0.0115, 0.0]), np.array([0.0, 0.0, 1.0]))]
    return parts, joints


def _upper_limb_parts(rings: int) -> tuple:
    ring = dict(rings=rings, segments=rings)
    # the arm's layout (humerus up +y, forearm along +x, elbow hinge about +z at
    # the origin) with a scapula across the humerus' top: the shoulder a ball
    # joint between them. The biceps (in front, +x) and the triceps (behind)
    # run from the scapula to the forearm clear of the humerus, spanning both
    # joints; the deltoid runs from the scapula's side (+z) to the humerus.
    parts = [
        PartSpec("scapula", capsule([-0.03, 0.152, 0], [0.03, 0.152, 0], 0.009, **ring), "bone"),
        PartSpec("humerus", capsule([0, 0.016, 0], [0, 0.132, 0], 0.008, **ring), "bone", fixed=False),
        PartSpec("forearm", capsule([-0.024, 0, 0], [0.125, 0, 0], 0.007, **ring), "bone", fixed=False),
        PartSpec("biceps", spindle([0.014, 0.146, 0], [0.04, 0.002, 0], 0.009, end_radius=0.003, **ring),
                 "muscle"),
        PartSpec("triceps", spindle([-0.016, 0.146, 0], [-0.02, 0.0, 0], 0.008, end_radius=0.003, **ring),
                 "muscle"),
        PartSpec("deltoid", spindle([0.0, 0.152, 0.012], [0.0, 0.09, 0.005], 0.007, end_radius=0.003, **ring),
                 "muscle"),
    ]
    joints = [JointSpec(("scapula", "humerus"), np.array([0.0, 0.1375, 0.0]), None),
              JointSpec(("humerus", "forearm"), np.array([0.0, 0.0115, 0.0]), np.array([0.0, 0.0, 1.0]))]
    return parts, joints


def _leg_parts(rings: int) -> tuple:
    ring = dict(rings=rings, segments=rings)
    # z up, the knee bent 15 degrees at rest: the tibia runs down and back (-y);
    # the hinge sits at the back of the joint so the quadriceps passes in front of it
    bend = np.radians(15)
    down = np.array([0.0, -np.sin(bend), -np.cos(bend)])
    front = np.array([0.0, np.cos(bend), -np.sin(bend)])
    parts = [
        PartSpec("femur", capsule([0, 0, 0.012], [0, 0, 0.2], 0.011, **ring), "bone"),
        PartSpec("tibia", capsule(0.012 * down, 0.19 * down, 0.009, **ring), "bone", fixed=False),
        PartSpec("hamstring", spindle([0, -0.006, 0.17], 0.04 * down - 0.008 * front, 0.014, end_radius=0.004,
                                      **ring), "muscle"),
        PartSpec("quadriceps", spindle([0, 0.009, 0.17], 0.03 * down + 0.0085 * front, 0.016, end_radius=0.004,
                                       **ring), "muscle"),
    ]
    joints = [JointSpec(("femur", "tibia"), np.array([0.0, -0.003, 0.0]), np.array([1.0, 0.0, 0.0]))]
    return parts, joints


def _neck_parts(rings: int) -> tuple:
    ring = dict(rings=rings, segments=rings)
    # x right, y front, z up; the head turns about a ball joint above the spine's
    # top, in the gap between the two bones
    parts = [PartSpec("torso", capsule([0, 0, -0.02], [0, 0, 0.06], 0.01, **ring), "bone"),
             PartSpec("head", capsule([-0.035, 0, 0.092], [0.035, 0, 0.092], 0.02, **ring), "bone",
                      fixed=False)]
    for name, x, y in (("left_back", -1, -1), ("right_back", 1, -1), ("left_front", -1, 1), ("right_front", 1, 1)):
        parts.append(PartSpec(name, spindle([0.006 * x, 0.006 * y, 0.0], [0.03 * x, 0.012 * y, 0.082], 0.008,
                                            end_radius=0.003, **ring), "muscle"))
    joints = [JointSpec(("torso", "head"), np.array([0.0, 0.0, 0.066]), None)]
    return parts, joints


_SHAPES = {"arm": _arm_parts, "leg": _leg_parts, "neck": _neck_parts, "upper_limb": _upper_limb_parts}


def _key(name: str, resolution: int, parts, joints) -> str:
    h = hashlib.sha1(f"{_VERSION} {name} {resolution}".encode())
    for p in parts:
        h.update(f"{p.name} {p.kind} {p.fixed}".encode())
        for a in p.surface:
            h.update(np.ascontiguousarray(a).tobytes())
    for j in joints:
        h.update(json.dumps([list(j.bones), j.centre.tolist(), None if j.axis is None else j.axis.tolist()]).encode())
    return f"{name}_r{resolution}_{h.hexdigest()[:12]}.npz"


def _build(name: str, resolution: int, progress=None) -> dict:
    """The meshed anatomy as arrays (from the cache, or meshed and cached)."""
    if not (isinstance(resolution, (int, np.integer)) and resolution >= 1):
        raise ValueError(f"resolution must be an integer >= 1, got {resolution!r}")
    parts, joints = _SHAPES[name](_rings(int(resolution)))
    key = _key(name, int(resolution), parts, joints)
    path = os.path.join(cache_dir(), key)
    for found in (os.path.join(SHIPPED_DIR, key), path):
        if os.path.exists(found):
            with np.load(found, allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
    if progress:
        progress(f"meshing the built-in {name} at resolution {resolution} (once; cached in {cache_dir()})")
    spec = PartsFile(path="", parts=parts, joints=joints, tets=int(ANATOMY_TETS * resolution ** 2))
    a = author(spec, threads=1, epsilon=_epsilon(int(resolution)))
    s = a.scene
    data = {"points": s.points, "tets": s.tets, "part": a.part, "fiber": a.fiber,
            "names": np.array(a.part_names), "kinds": np.array(a.part_kinds),
            "fixed": np.array([s.parts[n].kind != "bone" or s.parts[n].fixed for n in a.part_names]),
            "joint_bones": np.array([j["bones"] for j in a.joints]).reshape(-1, 2),
            "joint_centres": np.array([j["centre"] for j in a.joints], float).reshape(-1, 3),
            "joint_axes": np.array([np.full(3, np.nan) if j["axis"] is None else j["axis"] for j in a.joints],
                                   float).reshape(-1, 3)}
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = path + f".{os.getpid()}.tmp.npz"
    np.savez_compressed(tmp, **data)
    os.replace(tmp, path)   # atomic: a parallel build writes the same file
    return data


def _scene(name: str, resolution: int, *, fixed_bones=(), joint_stiffness=None, muscle_youngs: float = 6e4,
           max_activation: float = 1e5, progress=None) -> Scene:
    d = _build(name, resolution, progress)
    s = Scene(d["points"], d["tets"])
    for k, (n, kind) in enumerate(zip(d["names"].tolist(), d["kinds"].tolist())):
        idx = np.flatnonzero(d["part"] == k)
        if kind == "bone":
            s.add_bone(n, idx, fixed=bool(d["fixed"][k]) or n in fixed_bones,
                       joint_stiffness=(joint_stiffness or {}).get(n, 0.0))
        elif kind == "tendon":
            s.add_tendon(n, idx)
        else:
            s.add_muscle(n, idx, d["fiber"][idx], youngs=muscle_youngs, max_activation=max_activation)
    for (a, b), c, ax in zip(d["joint_bones"].tolist(), d["joint_centres"], d["joint_axes"]):
        if s.parts[a].fixed and s.parts[b].fixed:
            continue   # both held: the joint moves nothing
        s.add_joint(a, b, c, None if np.isnan(ax).any() else ax)
    return s


def arm(resolution: int = 3, *, forearm_fixed: bool = False, muscle_youngs: float = 6e4,
        max_activation: float = 1e5, progress=None) -> Scene:
    """The smooth arm (module docstring): about 6k tets at resolution 3."""
    return _scene("arm", resolution, fixed_bones=("forearm",) if forearm_fixed else (),
                  muscle_youngs=muscle_youngs, max_activation=max_activation, progress=progress)


def upper_limb(resolution: int = 3, *, shoulder_stiffness: float = SHOULDER_STIFFNESS, muscle_youngs: float = 6e4,
               max_activation: float = 1e5, progress=None) -> Scene:
    """The arm on a shoulder (module docstring): a chain of two movable bones.
    shoulder_stiffness (N m / rad) is the humerus' passive spring about the
    shoulder (a real shoulder's capsule and ligaments): with it, the muscles
    and not pins hold the humerus, and every activation has one equilibrium."""
    return _scene("upper_limb", resolution, joint_stiffness={"humerus": shoulder_stiffness},
                  muscle_youngs=muscle_youngs, max_activation=max_activation, progress=progress)


def leg(resolution: int = 3, *, muscle_youngs: float = 6e4, max_activation: float = 1e5, progress=None) -> Scene:
    """The smooth leg (module docstring): the hamstring flexes the knee, the quadriceps straightens it."""
    return _scene("leg", resolution, muscle_youngs=muscle_youngs, max_activation=max_activation, progress=progress)


def neck(resolution: int = 3, *, muscle_youngs: float = 6e4, max_activation: float = 1e5, progress=None) -> Scene:
    """The smooth neck (module docstring): four muscles turn the head on its ball joint."""
    return _scene("neck", resolution, muscle_youngs=muscle_youngs, max_activation=max_activation, progress=progress)


def _rebuild_shipped(names=None) -> None:
    """Mesh the shipped resolutions of the scenes ``names`` (default: all)
    afresh into SHIPPED_DIR, after a shape changed or a scene was added."""
    import glob
    import tempfile
    names = tuple(_SHAPES) if names is None else tuple(names)
    for name in names:
        for old in glob.glob(os.path.join(SHIPPED_DIR, f"{name}_r*.npz")):
            os.remove(old)
    os.makedirs(SHIPPED_DIR, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["EMU_CACHE_DIR"] = tmp
        for name in names:
            for r in SHIPPED_RESOLUTIONS:
                _build(name, r, progress=print)
        for f in sorted(os.listdir(os.path.join(tmp, "anatomy"))):
            os.replace(os.path.join(tmp, "anatomy", f), os.path.join(SHIPPED_DIR, f))
            print("shipped", f)
