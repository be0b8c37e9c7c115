"""The OpenSim ``arm26`` model's bones as an emu scene: real bone surfaces,
downloaded on first use, posed, given a biceps and a triceps, meshed.

    scene file:  [mesh] dataset = "arm26"      command line:  emu data arm26

What is built, and from what (the files of the ``opensim-org/opensim-models``
repository at a pinned commit, checked by SHA-256 in :mod:`emu.datasets`):

- the humerus (``Geometry/arm_r_humerus.vtp``), fixed: the shoulder holds it;
- the forearm: ulna and radius (``arm_r_ulna.vtp``, ``arm_r_radius.vtp``) as
  one bone of two shells, as arm26's body ``r_ulna_radius_hand`` has them,
  turned about arm26's ``r_elbow`` joint (centre and axis read from
  ``Models/Arm26/arm26.osim``) by ELBOW_FLEXION, and free to turn about that
  hinge;
- a biceps and a triceps: not anatomy but spindles laid along arm26's own
  muscle paths (``BIClong``, ``TRIlong``: MUSCLES names the path points),
  each end on the line from its path point to the nearest point inside
  its bone, END_DEPTH past the bone's surface, the belly an ellipse in
  section (wide across the arm,
  flat against it) bowed away from the bone (a parabola, largest at the
  middle), the biceps with a tendon at each end (TENDON_LENGTH).

The humerus frame's metres throughout (y up the arm, x forward, z the elbow
axis' direction). The bone shells are real-world input: none is closed, some
intersect themselves; the mesher's winding numbers close them, and the
report (``report.json``, ``emu info``) lists the defects.

Credit (the model's licence, Creative Commons CC BY 3.0, asks for it): the
OpenSim Development Team (Reinbolt, J; Seth, A; Habib, A; Hamner, S), adapted
from a model originally created by Kate Holzbaur; Holzbaur, Murray, Delp,
Annals of Biomedical Engineering 33, 829-840, 2005. Written beside the
built mesh as CREDITS.txt.
"""
from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET

import numpy as np

from .author import AuthoringError, JointSpec, PartSpec, PartsFile, author, winding_numbers, write_authored
from ..io.obj import write_obj
from ..io.vtk import read_polydata
from .shapes import spindle

__all__ = ["SURFACE_FILES", "MODEL_FILE", "ELBOW_FLEXION", "MUSCLES", "TETS", "CREDITS",
           "elbow_joint", "path_points", "surfaces", "parts", "build"]

SURFACE_FILES = {"humerus": "Geometry/arm_r_humerus.vtp", "ulna": "Geometry/arm_r_ulna.vtp",
                 "radius": "Geometry/arm_r_radius.vtp"}
MODEL_FILE = "Models/Arm26/arm26.osim"
# the pose: 90 degrees of elbow flexion (arm26's r_elbow_flex, range 0 to 130 degrees). At the
# model's default (0, elbow straight) the humerus' and ulna's shells touch, and a mesh welds them.
ELBOW_FLEXION = np.pi / 2
# Each muscle: its arm26 path, and the path points its ends are laid at (proximal, distal).
# BIClong-P4: the intertubercular groove; P9: the radial tuberosity. TRIlong-P2: the back of
# the humerus' shaft (the long head's origin, P1, is on the scapula, which is not modelled);
# P5: the olecranon, approached from END_SHIFT behind it.
MUSCLES = {"biceps": ("BIClong", "BIClong-P4", "BIClong-P9"),
           "triceps": ("TRIlong", "TRIlong-P2", "TRIlong-P5")}
END_SHIFT = {"TRIlong-P5": (-0.015, -0.005, 0.0)}   # m, humerus frame (posed)
END_DEPTH = 0.006          # m: how far each end reaches into its bone (the attachment)
# m: the belly's half-widths across and off the arm, and how far its middle stands off the line
# between its ends (the triceps' ends lie deep in the humerus' shaft and the olecranon)
BELLY = {"biceps": (0.016, 0.009, 0.009), "triceps": (0.018, 0.010, 0.022)}
END_RADIUS = 0.006         # m: the neck of each end (under the tet edge, the mesher loses it)
OUTWARD = {"biceps": (1.0, 0.0, 0.0), "triceps": (-1.0, 0.0, 0.0)}   # off the arm: forward, backward
# m: the tendon split off each end. None for the triceps: at 90 degrees the olecranon tucks under
# the humerus' distal end, the triceps wraps it, and a mesh attaches it to both bones a centimetre
# apart there (the tendon slides over the humerus in life); a stiff tendon there welds the elbow,
# the soft muscle only resists flexion, as the passive triceps does.
TENDON_LENGTH = {"biceps": 0.01, "triceps": None}
TETS = 15000               # the mesher's target (about 9k tets come out)
CREDITS = ("Bones of the OpenSim arm26 model (opensim-org/opensim-models, Geometry/arm_r_humerus.vtp, "
           "arm_r_ulna.vtp, arm_r_radius.vtp; Models/Arm26/arm26.osim). Credits: The OpenSim Development "
           "Team (Reinbolt, J; Seth, A; Habib, A; Hamner, S) adapted from a model originally created by "
           "Kate Holzbaur (11/22/04). Licence: Creative Commons CC BY 3.0 "
           "(http://creativecommons.org/licenses/by/3.0/). Publication: Holzbaur, K.R.S., Murray, W.M., "
           "Delp, S.L. A Model of the Upper Extremity for Simulating Musculoskeletal Surgery and Analyzing "
           "Neuromuscular Control. Annals of Biomedical Engineering 33, 829-840, 2005. Posed at 90 degrees "
           "of elbow flexion by emu; the biceps and triceps are emu's spindles along arm26's muscle paths.")


def _floats(text, n, where):
    try:
        v = np.array((text or "").split(), dtype=np.float64)
    except ValueError:
        v = np.zeros(0)
    if v.shape != (n,):
        raise ValueError(f"{where}: expected {n} numbers, got {text!r}")
    return v


def elbow_joint(osim) -> tuple:
    """arm26's elbow hinge in the humerus frame: (centre (3,), unit axis (3,)),
    from the ``r_elbow`` joint of the .osim file (its parent offset frame's
    translation; its ``rotation1`` axis). Raises ValueError for a model whose
    elbow has offset orientations or a child offset (not arm26's layout)."""
    root = ET.parse(os.fspath(osim)).getroot()
    joint = next((j for j in root.iter("CustomJoint") if j.get("name") == "r_elbow"), None)
    if joint is None:
        raise ValueError(f"{osim}: no CustomJoint 'r_elbow'")
    frames = {f.get("name"): f for f in joint.iter("PhysicalOffsetFrame")}
    try:
        parent, child = frames["r_humerus_offset"], frames["r_ulna_radius_hand_offset"]
    except KeyError:
        raise ValueError(f"{osim}: r_elbow lacks its offset frames (found {sorted(frames)})") from None
    centre = _floats(parent.findtext("translation"), 3, "r_humerus_offset translation")
    for f, what in ((parent, "orientation"), (child, "orientation"), (child, "translation")):
        if np.any(_floats(f.findtext(what), 3, f"{f.get('name')} {what}") != 0):
            raise ValueError(f"{osim}: r_elbow's {f.get('name')} has a non-zero {what}; "
                             "emu.arm26 reads arm26's layout only")
    axes = {t.get("name"): t for t in joint.iter("TransformAxis")}
    if "rotation1" not in axes or (axes["rotation1"].findtext("coordinates") or "").strip() != "r_elbow_flex":
        raise ValueError(f"{osim}: r_elbow's rotation1 is not driven by r_elbow_flex")
    axis = _floats(axes["rotation1"].findtext("axis"), 3, "r_elbow rotation1 axis")
    return centre, axis / np.linalg.norm(axis)


def path_points(osim, muscle: str) -> dict:
    """The path points of ``muscle`` in the .osim file: {name: (body, location (3,))},
    body the last part of the point's parent frame (e.g. ``r_humerus``)."""
    root = ET.parse(os.fspath(osim)).getroot()
    m = next((e for e in root.iter() if e.get("name") == muscle and e.find(".//PathPoint") is not None), None)
    if m is None:
        raise ValueError(f"{osim}: no muscle {muscle!r} with path points")
    return {p.get("name"): ((p.findtext("socket_parent_frame") or "").rsplit("/", 1)[-1],
                            _floats(p.findtext("location"), 3, f"{p.get('name')} location"))
            for p in m.iter("PathPoint")}


def _rotation(axis, angle) -> np.ndarray:
    """R = I + sin(t) K + (1 - cos(t)) K^2, K the cross-product matrix of the unit axis (Rodrigues)."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _sunk_end(bone, p, name):
    """Where a muscle's end goes: from path point p toward the nearest point
    inside the bone (winding number > 1/2, on a 1 mm grid within 3 cm), into
    the bone and END_DEPTH on, or to the middle of the bone along that line
    where it is thinner than 2 END_DEPTH."""
    V, F = bone
    g = np.arange(-0.03, 0.0301, 0.002)
    grid = p + np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    grid = grid[np.linalg.norm(grid - p, axis=1) <= 0.03]
    inside = winding_numbers(V, F, grid) > 0.5
    if not inside.any():
        raise ValueError(f"arm26: no point of the bone lies within 3 cm of {name} (the bone's surface changed?)")
    q = grid[inside][np.argmin(np.linalg.norm(grid[inside] - p, axis=1))]
    u = (q - p) / np.linalg.norm(q - p)
    t = np.arange(0.0, 0.05, 2.5e-4)             # up to 5 cm along the line, a quarter millimetre apart
    inside = winding_numbers(V, F, p + np.outer(t, u)) > 0.5
    t_in = t[np.argmax(inside)]
    after = ~inside & (t > t_in)
    t_out = t[np.argmax(after)] if after.any() else t[-1]
    return p + min(t_in + END_DEPTH, 0.5 * (t_in + t_out)) * u


def _muscle(p0, p1, belly, outward, rings, segments):
    """A spindle from p0 to p1 whose section is an ellipse, belly = (half-width
    across the arm, half-width along ``outward``, bow h): bowed outward by
    x += 4 s (1 - s) h d, s in [0, 1] along p0 -> p1."""
    across, off, bow = belly
    V, F = spindle(p0, p1, across, rings=rings, segments=segments, end_radius=END_RADIUS)
    length = np.linalg.norm(p1 - p0)
    axis = (p1 - p0) / length
    d = np.asarray(outward, np.float64)
    d = d - axis * (d @ axis)
    d /= np.linalg.norm(d)
    V = V - np.outer((V - p0) @ d, d) * (1 - off / across)      # the section flattened along d
    s = np.clip((V - p0) @ axis / length, 0.0, 1.0)
    return V + np.outer(4 * s * (1 - s) * bow, d), F


def _joined(a, b):
    """Two surfaces (V, F) as one of two shells."""
    return np.vstack([a[0], b[0]]), np.vstack([a[1], b[1] + len(a[0])])


def surfaces(files: dict, *, rings: int = 20, segments: int = 24) -> dict:
    """The posed surfaces, {name: (V (n, 3), F (f, 3))}: humerus, ulna, radius (the
    forearm's two shells), biceps, triceps. ``files``: {repository path: local path}
    for SURFACE_FILES' and MODEL_FILE's paths."""
    osim = files[MODEL_FILE]
    centre, axis = elbow_joint(osim)
    R = _rotation(axis, ELBOW_FLEXION)

    def pose(body, x):
        # a point of r_ulna_radius_hand in the humerus frame: turned about the elbow, moved to its centre
        return x @ R.T + centre if body == "r_ulna_radius_hand" else x

    out = {}
    for name, rel in SURFACE_FILES.items():
        V, F = read_polydata(files[rel])
        out[name] = (pose("r_humerus" if name == "humerus" else "r_ulna_radius_hand", V), F)
    bone_of = {"r_humerus": out["humerus"], "r_ulna_radius_hand": _joined(out["ulna"], out["radius"])}
    for name, (path, first, last) in MUSCLES.items():
        pts = path_points(osim, path)
        ends = []
        for pname in (first, last):
            body, loc = pts[pname]
            if body not in bone_of:
                raise ValueError(f"{osim}: {pname} is on {body}, which emu.arm26 does not model")
            p = pose(body, loc) + np.asarray(END_SHIFT.get(pname, (0.0, 0.0, 0.0)))
            ends.append(_sunk_end(bone_of[body], p, pname))
        out[name] = _muscle(ends[0], ends[1], BELLY[name], OUTWARD[name], rings, segments)
    return out


def parts(files: dict, *, tets: int = TETS) -> PartsFile:
    """The scene's parts as `emu.author` takes them (surfaces as arrays): the
    humerus (fixed), the forearm (ulna + radius, free), biceps, triceps, and
    the declared elbow hinge."""
    s = surfaces(files)
    centre, axis = elbow_joint(files[MODEL_FILE])
    return PartsFile(path="", parts=[
        PartSpec("humerus", s["humerus"], "bone"),
        PartSpec("forearm", _joined(s["ulna"], s["radius"]), "bone", fixed=False),
        PartSpec("biceps", s["biceps"], "muscle", tendon_length=TENDON_LENGTH["biceps"]),
        PartSpec("triceps", s["triceps"], "muscle", tendon_length=TENDON_LENGTH["triceps"]),
    ], joints=[JointSpec(("humerus", "forearm"), centre, axis)], tets=tets)


def build(files: dict, out_dir, *, tets: int = TETS, progress=None) -> dict:
    """Mesh the scene into out_dir: what `emu mesh` writes (mesh.vtu, scene.json,
    scene.toml, report.json, mesh.png), the posed surfaces as OBJ with a parts
    file that remeshes them (``emu mesh surfaces/parts.toml``), and CREDITS.txt.
    Returns {name: path}."""
    out_dir = os.fspath(out_dir)
    spec = parts(files, tets=tets)
    sdir = os.path.join(out_dir, "surfaces")
    os.makedirs(sdir, exist_ok=True)
    lines = ["# The arm26 scene's surfaces (emu.arm26): emu mesh parts.toml --out mesh", "[mesh]",
             f"tets = {tets}", ""]
    for p in spec.parts:
        write_obj(os.path.join(sdir, f"{p.name}.obj"), *p.surface)
        lines += ["[[part]]", f'name = "{p.name}"', f'surface = "{p.name}.obj"', f'kind = "{p.kind}"']
        lines += ["fixed = false"] if p.kind == "bone" and not p.fixed else []
        lines += [f"tendon_length = {p.tendon_length:g}"] if p.tendon_length else []
        lines.append("")
    for j in spec.joints:
        lines += ["[[joint]]", f"bones = {json.dumps(list(j.bones))}",
                  f"centre = [{', '.join(f'{c:.9g}' for c in j.centre)}]",
                  f"axis = [{', '.join(f'{c:.9g}' for c in j.axis)}]", ""]
    with open(os.path.join(sdir, "parts.toml"), "w") as f:
        f.write("\n".join(lines))
    if progress:
        progress(f"meshing arm26 (about {tets * 3 // 5} tets; once, cached in {out_dir})")
    try:
        result = author(spec)
    except AuthoringError as e:
        raise AuthoringError(f"arm26: {e}") from None
    paths = write_authored(result, out_dir)
    with open(os.path.join(out_dir, "CREDITS.txt"), "w") as f:
        f.write(CREDITS + "\n")
    paths["credits"] = os.path.join(out_dir, "CREDITS.txt")
    paths["surfaces"] = sdir
    return paths
