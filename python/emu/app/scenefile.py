"""Scene files (TOML or JSON): one documented schema, a typed loader, clear errors.

    pins = ["proximal"]          # top level (before any [table] in TOML): named sets and/or
                                 # vertex ids
    gravity = [0.0, 0.0, 0.0]

    [mesh]                       # exactly one of: path | dataset | [mesh.fusiform] | [mesh.arm] | [mesh.neck]
                                 # | [mesh.leg] | [mesh.upper_limb] | [mesh.elbow_wrap]
    path = "muscle.vtu"          # a labelled mesh file, relative to the scene file
    dataset = "big_muscle"       # or one of the authors' research scenes (simple_joint, big_muscle,
                                 # realistic_biceps), downloaded on first use (emu.datasets, `emu data`)
    fibers = "file"              # muscles' fibres: "file" (cell data) or "laplace" (between attachments)
    weld = false                 # merge vertices at the same point (parts meshed apart; ids change)
    [mesh.arm]                   # the built-in arm of `emu demo` (emu.anatomy, smooth shapes meshed once and
                                 # cached): bones "humerus" (fixed) and
    resolution = 2               # "forearm" (moved by the muscles) on a hinge, muscles "flexor"
                                 # and "extensor" (Laplace fibres)
    [mesh.elbow_wrap]            # the arm's bones and flexor, and an extensor one block clear of the
    resolution = 2               # bones behind the elbow (emu.scenes.elbow_wrap): for contact
    [mesh.neck]                  # a head on a ball joint: bones "torso" (fixed) and "head" (moved),
    resolution = 2               # muscles "left_back", "right_back", "left_front", "right_front"
    [mesh.leg]                   # femur (fixed) and tibia (moved) on the knee hinge, bent 15 degrees;
    resolution = 2               # muscles "hamstring" (flexes the knee) and "quadriceps"
    [mesh.upper_limb]            # the arm on a shoulder: "scapula" (fixed), "humerus" on the shoulder's
    resolution = 2               # ball joint, "forearm" on the elbow hinge (a chain of two moved bones);
    shoulder_stiffness = 0.05    # muscles "biceps", "triceps" (both joints), "deltoid"; the humerus'
                                 # passive spring (N m / rad)
    [mesh.fusiform]              # the procedural muscle (emu.scenes.fusiform): parts "belly"
    tets = 5000                  # and "tendons", pin sets "proximal" and "distal"
    length = 10.0
    radius = 1.5
    end_radius = 0.5
    tendon_fraction = 0.12

    [parts.belly]                # mesh.path / mesh.dataset: what a labelled part is
    kind = "muscle"              # muscle | tendon | bone (default: the scene.json beside the mesh, else
                                 # muscle); gmsh physical names and `emu mesh` name the parts
    fibers = "laplace"           # muscles: "file", "laplace" or a direction [x, y, z] (others: mesh.fibers)

    [materials.belly]            # per-part overrides (any of the keys)
    youngs = 6e4
    poisson = 0.49
    density = 1060.0
    max_activation = 1e5
    acap_weight = 1.0

    [solver]                     # emu.Solver's options (emu.options.OPTIONS; docs/guide/options.md),
    method = "emu"               # or "fem"; an option of the other method is an error naming it
    accuracy = 0.01              # the vertex error to FEM wanted (1% of the diagonal): picks alpha
                                 # and stops iterating when steps no longer matter
    threads = 2

    [contact]                    # surfaces that touch without passing through (FEM; needs ipctk)
    pairs = [["flexor", "humerus"]]   # parts that may touch (omit: every pair but bone-bone)
    self_contact = false
    distance = 0.002             # the barrier's reach in scene units (omit: 5e-3 x the diagonal,
                                 # at most half the smallest rest gap)
    stiffness = 2e4              # the barrier's pressure scale, Pa (omit: the softest muscle's mu)

    [frames]
    count = 30
    dt = 0.0333                  # seconds per frame: frame k is at time k * dt

    [dynamics]                   # time steps with inertia instead of equilibria: each frame one
    integrator = "bdf2"          # step of frames.dt from the frame before (frame 0: from rest),
    mass_damping = 0.0           # masses from the materials' densities; "bdf2" (second order) or
                                 # "backward_euler" (damps vibrations numerically); mass_damping:
                                 # Rayleigh's c, 1/s

    [activation.belly]           # one table per muscle; muscles not listed stay at 0
    keys = [[0.0, 0.0], [0.5, 1.0], [1.0, 0.0]]   # [time, value]; or per_frame = [...]
    interpolation = "smooth"     # "linear", "smooth" or "step"
    normalized = true            # values in [0, 1] x max_activation; false: absolute a

    [bones.ulna]                 # a bone the muscles move (rigid, turning about its joints)
    fixed = false
    acap_weight = 1e4            # EMU's ACAP weight on its tets (rigidity of the fitted positions)
    joint_stiffness = 0.0        # passive spring against turning from rest, N m / rad

    [joints.elbow]               # a joint declared where two bones do not touch (joints at
    bones = ["ulna", "humerus"]  # shared vertices are found by themselves): a ball joint at
    centre = [0.0, 0.0, 0.0]     # `centre`, or with `axis` a hinge about the line through it
    axis = [0.0, 0.0, 1.0]

    [bones.radius]               # a scripted bone (fixed bones, the default, may be scripted):
    axis = [0.0, 0.0, 1.0]       # rotation axis through `centre`, angle keyframes in degrees
    centre = [0.0, 0.0, 0.0]
    angle = [[0.0, 0.0], [1.0, 30.0]]
    interpolation = "smooth"

    [output]
    dir = "emu_run"              # `emu run --out` overrides it
    vtu = true                   # a VTU per frame and a .pvd series (ParaView)
    obj = true                   # an OBJ surface per frame (Blender)
    preview = true               # preview.png: up to eight frames, shaded, per-part colours
    usd = false                  # run.usd: one animated USD stage (needs emu[usd]): bones as rigid
                                 # transforms, soft parts as meshes with activation / J / fibre
                                 # primvars and as tet meshes
    meters_per_unit = 1.0        # what one scene unit is in metres (the USD stage's metersPerUnit)
    view = "yz"                  # the preview's right and up axes (default: looking along the first
                                 # hinge, else along the mesh's thinnest side)

Centre is spelled ``centre`` everywhere (a ``center`` key is an error that says so).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..solve.frames import Frame
from ..solve.dynamics import Dynamics
from ..solve.options import METHODS, check_options, scene_file_types
from ..core.activation import Curve
from ..build import datasets
from ..io.mesh import load_scene
from ..model.parts import lame
from ..core.poses import pose_about
from ..build import anatomy
from ..build.scenes import elbow_wrap, fusiform

__all__ = ["SceneSpec", "load_scene_file", "SceneFileError"]


class SceneFileError(ValueError):
    """A scene file that does not follow the schema (the message names the key)."""


# the built-in scenes a [mesh.NAME] table names
_BUILT_IN = ("arm", "neck", "leg", "upper_limb", "elbow_wrap")

_SCHEMA = {
    "mesh": {"path": str, "dataset": str, "fibers": str, "weld": bool, "fusiform": {"tets": int, "resolution": int, "length": float,
                                                     "radius": float, "end_radius": float,
                                                     "tendon_fraction": float},
             "arm": {"resolution": int}, "neck": {"resolution": int}, "leg": {"resolution": int},
             "upper_limb": {"resolution": int, "shoulder_stiffness": float}, "elbow_wrap": {"resolution": int}},
    "materials": "table of tables",
    "parts": "table of tables",
    "pins": list,
    "gravity": list,
    "solver": scene_file_types(),   # emu.options.OPTIONS: the Solver's options, written once
    "frames": {"count": int, "dt": float},
    "dynamics": {"integrator": str, "mass_damping": float},
    "contact": {"pairs": list, "self_contact": bool, "distance": float, "stiffness": float},
    "activation": "table of tables",
    "bones": "table of tables",
    "joints": "table of tables",
    "output": {"dir": str, "vtu": bool, "obj": bool, "preview": bool, "view": str, "usd": bool,
               "meters_per_unit": float},
}
_BONE_KEYS = {"fixed": bool, "acap_weight": float, "joint_stiffness": float, "axis": list, "centre": list,
              "angle": list, "interpolation": str}
_JOINT_KEYS = {"bones": list, "centre": list, "axis": list}
_PART_KEYS = {"kind": str, "fibers": (str, list)}
_MATERIAL_KEYS = {"youngs": float, "poisson": float, "density": float, "max_activation": float,
                  "acap_weight": float, "joint_stiffness": float}
_CURVE_KEYS = {"keys": list, "per_frame": list, "interpolation": str, "normalized": bool}


@dataclass
class SceneSpec:
    scene: object                         # emu.Scene
    solver: dict                          # emu.Solver keyword arguments (method included)
    frames: int
    dt: float
    curves: dict                          # muscle name -> Curve
    bones: dict = field(default_factory=dict)  # scripted bone -> (axis (3,), centre (3,), angle Curve)
    output: dict = field(default_factory=lambda: {"dir": "emu_run", "vtu": True, "obj": True, "preview": True,
                                                  "view": None, "usd": False})
    source: str = ""
    mesh_path: str = ""                   # the mesh file mesh.path / mesh.dataset loaded ("" for built-in scenes)
    dynamics: object = None               # an emu.Dynamics ([dynamics]): frames are time steps; None: equilibria

    def bone_poses(self, frame: int) -> dict:
        """{bone: (R, t)} of the scripted bones at a frame."""
        t = frame * self.dt
        return {name: pose_about(axis, curve.value(frame, t), centre)
                for name, (axis, centre, curve) in self.bones.items()}

    def activation(self, frame: int) -> dict:
        """{muscle: absolute a} at a frame."""
        t = frame * self.dt
        out = {}
        for name, c in self.curves.items():
            v = c.value(frame, t)
            out[name] = v * self.scene.parts[name].max_activation if c.normalized else v
        return out

    def frame(self, k: int) -> Frame:
        """Frame k's load: the activations and the scripted bones' poses."""
        return Frame(activation=self.activation(k), bone_poses=self.bone_poses(k))

    def frame_loads(self, frames=None) -> list:
        """The loads of ``frames`` (frame numbers; None: every frame), for emu.solve_frames."""
        return [self.frame(k) for k in (range(self.frames) if frames is None else frames)]


def _type_ok(value, kind) -> bool:
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, kind)


def _check_table(table, schema, where):
    if not isinstance(table, dict):
        raise SceneFileError(f"{where} must be a table, got {type(table).__name__}")
    for key, value in table.items():
        if key == "center" and "centre" in schema:
            name = f"{where}.center" if where else "center"
            raise SceneFileError(f"'{name}': spell it 'centre' (emu uses the one spelling)")
        if key not in schema:
            raise SceneFileError(f"unknown key '{where}.{key}' (allowed: {', '.join(sorted(schema))})"
                                 if where else f"unknown key '{key}' (allowed: {', '.join(sorted(schema))})")
        kind = schema[key]
        name = f"{where}.{key}" if where else key
        if isinstance(kind, dict):
            _check_table(value, kind, name)
        elif kind == "table of tables":
            if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
                raise SceneFileError(f"'{name}' must be a table of tables ([{name}.<part name>])")
        elif not _type_ok(value, kind):
            want = " or ".join(k.__name__ for k in kind) if isinstance(kind, tuple) else kind.__name__
            raise SceneFileError(f"'{name}' must be {want}, got {type(value).__name__} ({value!r})")


# Files that are meshes or surfaces, not scene files (emu run given one says what to do instead).
_MESH_SUFFIXES = (".msh", ".vtu", ".vtk", ".mesh", ".node", ".ele", ".xdmf", ".med", ".inp", ".obj", ".stl",
                  ".ply", ".off")


def _read(path: str) -> dict:
    if not os.path.exists(path):
        raise FileNotFoundError(f"scene file not found: {path}")
    if path.lower().endswith(_MESH_SUFFIXES):
        raise SceneFileError(f"{path} is a mesh, not a scene file (.toml or .json): solve it at one activation "
                             f"with `emu solve {path}`, or name it in a scene file ([mesh] path = "
                             f"\"{os.path.basename(path)}\") to run frames; a parts file of surfaces goes to "
                             "`emu mesh`")
    with open(path, "rb") as f:
        raw = f.read()
    if path.endswith(".json"):
        try:
            return json.loads(raw)
        except json.JSONDecodeError as e:
            raise SceneFileError(f"{path}: not valid JSON: {e}") from None
    try:
        import tomllib
    except ModuleNotFoundError:  # Python < 3.11
        import tomli as tomllib
    try:
        return tomllib.loads(raw.decode())
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(f"{path}: not valid TOML: {e}") from None


def load_scene_file(path) -> SceneSpec:
    """Read and validate a scene file; build its Scene."""
    path = os.fspath(path)
    data = _read(path)
    _check_table(data, _SCHEMA, "")
    scene, mpath = _mesh_scene(data, os.path.dirname(os.path.abspath(path)))
    _apply_materials(scene, data.get("materials", {}))
    _apply_pins(scene, data.get("pins", []))
    _apply_gravity_and_contact(scene, data)
    solver = _solver_table(data.get("solver", {}))
    frames = data.get("frames", {})
    count, dt = int(frames.get("count", 1)), float(frames.get("dt", 1.0))
    if count < 1 or dt <= 0:
        raise SceneFileError(f"frames.count must be >= 1 and frames.dt > 0, got {count}, {dt}")
    curves = {name: _activation_curve(scene, name, spec, count) for name, spec in data.get("activation", {}).items()}
    bones = {}
    for name, spec in data.get("bones", {}).items():
        script = _bone_table(scene, name, spec)
        if script is not None:
            bones[name] = script
    for name, spec in data.get("joints", {}).items():
        _add_joint(scene, name, spec)
    if not scene.muscles and not bones and not np.any(scene.gravity):
        # nothing drives it: every frame would be the rest shape
        raise SceneFileError(
            "the scene has no muscle, no scripted bone and no gravity: nothing moves it, every frame would be "
            "its rest shape; make a part a muscle ([parts.<name>] kind = \"muscle\" for mesh.path / "
            "mesh.dataset), script a bone ([bones.<name>] axis, centre, angle) or set gravity")
    return SceneSpec(scene=scene, solver=solver, frames=count, dt=dt, curves=curves, bones=bones,
                     output=_output_table(data.get("output", {})), source=path, mesh_path=mpath,
                     dynamics=_dynamics_table(data, dt))


def _dynamics_table(data: dict, dt: float):
    """[dynamics] as an emu.Dynamics stepping frames.dt, or None."""
    if "dynamics" not in data:
        return None
    table = data["dynamics"]
    try:
        return Dynamics(dt, table.get("integrator", "bdf2"), float(table.get("mass_damping", 0.0)))
    except ValueError as e:
        raise SceneFileError(str(e)) from None


def _mesh_scene(data: dict, base: str) -> tuple:
    """(the Scene, the mesh file read or "") of the [mesh] table: a file, a
    research dataset, a built-in anatomy or the procedural fusiform."""
    mesh = data.get("mesh")
    if mesh is None:
        raise SceneFileError("missing [mesh] table (mesh.path, mesh.dataset or [mesh.fusiform])")
    if sum(k in mesh for k in ("path", "dataset", "fusiform") + _BUILT_IN) != 1:
        raise SceneFileError("[mesh] needs exactly one of 'path', 'dataset', [mesh.fusiform], [mesh.arm], "
                             "[mesh.neck], [mesh.leg], [mesh.upper_limb] or [mesh.elbow_wrap]")
    for key in ("fibers", "weld"):
        if key in mesh and not ("path" in mesh or "dataset" in mesh):
            raise SceneFileError(f"mesh.{key} applies to mesh.path or mesh.dataset only")
    if "path" in mesh or "dataset" in mesh:
        return _mesh_file_scene(data, mesh, base)
    if "parts" in data:
        raise SceneFileError("[parts.<name>] (kind, fibers) applies to mesh.path or mesh.dataset only")
    if any(k in mesh for k in _BUILT_IN):
        return _built_in_scene(mesh), ""
    return fusiform(**mesh["fusiform"], pins=()), ""


def _mesh_file_scene(data: dict, mesh: dict, base: str) -> tuple:
    """(Scene, path) of mesh.path or mesh.dataset, with [parts.<name>] kinds and fibres."""
    if "path" in mesh:
        mpath = mesh["path"] if os.path.isabs(mesh["path"]) else os.path.join(base, mesh["path"])
        if not os.path.exists(mpath):
            raise FileNotFoundError(f"mesh.path: file not found: {mpath}")
    else:
        if mesh["dataset"] not in datasets.names():
            raise SceneFileError(f"mesh.dataset: unknown research scene {mesh['dataset']!r} "
                                 f"(known: {', '.join(datasets.names())})")
        mpath = datasets.path(mesh["dataset"])
    fib = mesh.get("fibers", "file")
    if fib not in ("file", "laplace"):
        raise SceneFileError(f"mesh.fibers must be 'file' or 'laplace', got {fib!r}")
    kinds, per_part = {}, {}
    for name, table in data.get("parts", {}).items():
        _check_table(table, _PART_KEYS, f"parts.{name}")
        if "kind" in table:
            kinds[name] = table["kind"]
        if "fibers" in table:
            per_part[name] = table["fibers"]
    try:   # mesh.fibers for the muscles [parts] does not name
        scene = load_scene(mpath, fibers=per_part or fib, kinds=kinds, weld=mesh.get("weld", False),
                           other_fibers=mesh.get("fibers") if per_part else None)
    except ValueError as e:
        raise SceneFileError(f"mesh.path {mesh.get('path') or mesh.get('dataset')}: {e}") from None
    return scene, mpath


def _built_in_scene(mesh: dict):
    """The built-in anatomy [mesh.<kind>] names, at its resolution and options."""
    kind = next(k for k in _BUILT_IN if k in mesh)
    options = dict(mesh[kind])
    res = int(options.pop("resolution", 2))
    if res < 1:
        raise SceneFileError(f"mesh.{kind}.resolution must be >= 1, got {res}")
    if options.get("shoulder_stiffness", 0.0) < 0:
        raise SceneFileError(f"mesh.{kind}.shoulder_stiffness must be >= 0, got {options['shoulder_stiffness']}")
    return {"arm": anatomy.arm, "neck": anatomy.neck, "leg": anatomy.leg, "upper_limb": anatomy.upper_limb,
            "elbow_wrap": elbow_wrap}[kind](res, **options)


def _apply_materials(scene, materials: dict) -> None:
    """[materials.<part>] overrides, each checked (lame) as it is set."""
    for part, over in materials.items():
        if part not in scene.parts:
            raise SceneFileError(f"materials.{part}: no part named '{part}' (parts: {', '.join(scene.parts)})")
        _check_table(over, _MATERIAL_KEYS, f"materials.{part}")
        p = scene.parts[part]
        for k, v in over.items():
            setattr(p, k, float(v))
        lame(p.youngs, p.poisson)


def _apply_pins(scene, items: list) -> None:
    """pins: vertex ids or the names of the scene's pin sets."""
    named_pins, pins = scene.vertex_sets, []
    for i, item in enumerate(items):
        if isinstance(item, str):
            if item not in named_pins:
                raise SceneFileError(f"pins[{i}]: unknown pin set '{item}' (known: {', '.join(named_pins) or 'none'})")
            pins.append(np.asarray(named_pins[item]))
        elif _type_ok(item, int):
            pins.append(np.array([item]))
        else:
            raise SceneFileError(f"pins[{i}] must be a vertex id or a pin-set name, got {item!r}")
    if pins:
        scene.pin(np.concatenate(pins))


def _apply_gravity_and_contact(scene, data: dict) -> None:
    if "gravity" in data:
        g = data["gravity"]
        if len(g) != 3 or not all(_type_ok(v, float) for v in g):
            raise SceneFileError(f"gravity must be three numbers, got {g!r}")
        scene.gravity = np.asarray(g, dtype=np.float64)
    if "contact" in data:
        c = data["contact"]
        pairs = c.get("pairs")
        if pairs is not None and not all(isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p)
                                         for p in pairs):
            raise SceneFileError(f"contact.pairs must be a list of [part, part] name pairs, got {pairs!r}")
        try:
            scene.enable_contact(pairs, self_contact=bool(c.get("self_contact", False)),
                                 distance=c.get("distance"), stiffness=c.get("stiffness"))
        except ValueError as e:
            raise SceneFileError(f"contact: {e}") from None


def _solver_table(table: dict) -> dict:
    """[solver]: the method and emu.Solver's options, checked before anything runs."""
    solver = dict(table)
    method = solver.get("method", "emu")
    if method not in METHODS:
        raise SceneFileError(f"solver.method must be \"emu\" or \"fem\", got {method!r}")
    try:   # an option of the other method is an error here, before anything runs
        check_options(method, solver.get("step", "newton-krylov"), {k: v for k, v in solver.items() if k != "method"})
    except ValueError as e:
        raise SceneFileError(f"solver.{e}") from None
    return solver


def _activation_curve(scene, name: str, spec: dict, count: int) -> Curve:
    """[activation.<muscle>]: its curve over the frames."""
    if name not in scene.muscles:
        raise SceneFileError(f"activation.{name}: no muscle named '{name}' (muscles: {', '.join(scene.muscles)})")
    _check_table(spec, _CURVE_KEYS, f"activation.{name}")
    try:
        curve = Curve(keys=spec.get("keys"), per_frame=spec.get("per_frame"),
                      interpolation=spec.get("interpolation", "linear"), normalized=spec.get("normalized", True))
    except ValueError as e:
        raise SceneFileError(f"activation.{name}: {e}") from None
    if curve.per_frame is not None and len(curve.per_frame) < count:
        raise SceneFileError(f"activation.{name}.per_frame has {len(curve.per_frame)} values for {count} frames")
    return curve


def _bone_table(scene, name: str, spec: dict):
    """[bones.<name>]: the bone's settings applied; (axis, centre, angle Curve)
    where it is scripted, else None."""
    part = scene.parts.get(name)
    if part is None or part.kind != "bone":
        known = [p.name for p in scene.parts.values() if p.kind == "bone"]
        raise SceneFileError(f"bones.{name}: no bone named '{name}' (bones: {', '.join(known) or 'none'})")
    _check_table(spec, _BONE_KEYS, f"bones.{name}")
    if "fixed" in spec:
        part.fixed = bool(spec["fixed"])
    if "joint_stiffness" in spec:
        if not spec["joint_stiffness"] >= 0:
            raise SceneFileError(f"bones.{name}.joint_stiffness must be >= 0, got {spec['joint_stiffness']!r}")
        part.joint_stiffness = float(spec["joint_stiffness"])
    if "acap_weight" in spec:
        if not spec["acap_weight"] > 0:
            raise SceneFileError(f"bones.{name}.acap_weight must be positive, got {spec['acap_weight']!r}")
        part.acap_weight = float(spec["acap_weight"])
    scripted = [k for k in ("axis", "centre", "angle") if k in spec]
    if not scripted:
        return None
    if not part.fixed:
        raise SceneFileError(f"bones.{name}: a bone moved by the muscles (fixed = false) cannot be scripted "
                             f"({', '.join(scripted)} given)")
    return _bone_script(name, spec)


def _bone_script(name: str, spec: dict) -> tuple:
    """(axis, centre, angle Curve) of a scripted bone."""
    for key in ("axis", "centre", "angle"):
        if key not in spec:
            raise SceneFileError(f"bones.{name}: missing '{key}' (a scripted bone needs axis, centre, angle)")
    for key in ("axis", "centre"):
        v = spec[key]
        if len(v) != 3 or not all(_type_ok(x, float) for x in v):
            raise SceneFileError(f"bones.{name}.{key} must be three numbers, got {v!r}")
    if not any(spec["axis"]):
        raise SceneFileError(f"bones.{name}.axis must be non-zero")
    try:
        curve = Curve(keys=spec["angle"], interpolation=spec.get("interpolation", "linear"), signed=True)
    except ValueError as e:
        raise SceneFileError(f"bones.{name}.angle: {e}") from None
    return np.asarray(spec["axis"], float), np.asarray(spec["centre"], float), curve


def _add_joint(scene, name: str, spec: dict) -> None:
    """[joints.<name>]: a declared joint between two bones."""
    _check_table(spec, _JOINT_KEYS, f"joints.{name}")
    for key in ("bones", "centre"):
        if key not in spec:
            raise SceneFileError(f"joints.{name}: missing '{key}'")
    b = spec["bones"]
    if len(b) != 2 or not all(isinstance(x, str) for x in b):
        raise SceneFileError(f"joints.{name}.bones must be two bone names, got {b!r}")
    for key in ("centre", "axis"):
        v = spec.get(key)
        if v is not None and (len(v) != 3 or not all(_type_ok(x, float) for x in v)):
            raise SceneFileError(f"joints.{name}.{key} must be three numbers, got {v!r}")
    try:
        scene.add_joint(b[0], b[1], spec["centre"], spec.get("axis"))
    except ValueError as e:
        raise SceneFileError(f"joints.{name}: {e}") from None


def _output_table(table: dict) -> dict:
    """[output] with its defaults; view as two axis indices."""
    output = {"dir": "emu_run", "vtu": True, "obj": True, "preview": True, "view": None, "usd": False,
              "meters_per_unit": 1.0}
    output.update(table)
    if not output["meters_per_unit"] > 0:
        raise SceneFileError(f"output.meters_per_unit must be positive, got {output['meters_per_unit']!r}")
    if output["view"] is not None:
        v = output["view"]
        if len(v) != 2 or v[0] == v[1] or not set(v) <= set("xyz"):
            raise SceneFileError(f"output.view must be two different axes of x, y, z (right then up, e.g. "
                                 f"\"yz\"), got {v!r}")
        output["view"] = tuple("xyz".index(c) for c in v)
    return output
