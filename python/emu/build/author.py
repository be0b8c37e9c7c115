"""Authoring: one closed surface per part (OBJ, STL, PLY, OFF: what meshio
reads) meshed into ONE conforming, labelled tet mesh, a Scene and a scene
file (`emu mesh PARTS.toml --out DIR`).

The mesher is fTetWild through pytetwild's CSG entry (the extra emu[mesh]): the
union of all surfaces, every tet labelled with the input surface that holds
it by fTetWild's winding-number test, so surfaces with small holes or
overlaps still mesh. Overlap rule: where surfaces overlap the part listed
later in the mesher's order wins, and that order is muscles, then tendons,
then bones (each kind in the parts file's order): overlap goes to the bone,
and the muscle shares the interface's vertices with it (its attachment); a
tendon surface overlapping a muscle's end takes that end. Two muscles (or two
tendons) that overlap are reported as a defect. The parts file::

    [mesh]
    tets = 15000              # approximate target; or edge_length = 0.2 (surface units)
    [[part]]
    name = "humerus"
    surface = "humerus.obj"   # relative to the parts file
    kind = "bone"             # muscle | tendon | bone
    fixed = true              # bones: fixed (default) or moved by the muscles
    [[part]]
    name = "biceps"
    surface = "biceps.obj"
    kind = "muscle"
    tendon_length = 0.5       # muscles, optional: tets within this distance of an
                              # attachment become the tendon "<name>_tendon"
    fibers = [0.0, 0.0, 1.0]  # muscles, optional: one direction (default: the Laplace
                              # field between its two attachments)
    [[joint]]                 # optional: declared joints; without them, detected ones
    bones = ["humerus", "forearm"]
    centre = [0.0, 0.75, 10.45]
    axis = [1.0, 0.0, 0.0]    # no axis: a ball joint

Detected joints: two bones whose surfaces come within JOINT_GAP tet edges of
each other (and share no vertex) get a ball joint at the middle of their
closest points, when one of them is movable and no joint between them is
declared; the report and the scene file list them for the user to confirm
(or to give an axis).
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from dataclasses import dataclass, field

import numpy as np

from ..core.fibers import laplace_fibers
from ..io.plots import mesh_picture
from ..model.joints import joint_loop, loop_note
from ..model.scene import Scene

__all__ = ["PartSpec", "JointSpec", "PartsFile", "AuthoredScene", "read_parts", "read_surface",
           "surface_defects", "self_intersections", "tetrahedralize", "author", "write_authored", "AuthoringError"]

KINDS = ("muscle", "tendon", "bone")
# Mesher order (later wins an overlap): bones last, so overlap goes to the bone.
_MESH_ORDER = {"muscle": 0, "tendon": 1, "bone": 2}
# Two bones closer than JOINT_GAP tet edges (and not touching) get a detected ball joint.
JOINT_GAP = 3.0
# fTetWild's tets per volume for an ideal edge length e, with its coarsening on:
# about V / (TETS_PER_EDGE_CUBE e^3) tets (the coefficient varies a little with the shapes).
TETS_PER_EDGE_CUBE = 0.04
# Soft parts overlapping each other: a sample of OVERLAP_SAMPLE tets of the part
# that took the overlap, reported when more than OVERLAP_REPORTED of it lies
# inside the other's surface.
OVERLAP_SAMPLE, OVERLAP_REPORTED = 64, 0.05
# A muscle with one attachment runs its fibres from it to the far end: the
# muscle's vertices at least this fraction of its largest distance from the attachment.
FAR_END = 0.95
_PART_KEYS = {"name": str, "surface": str, "kind": str, "fixed": bool, "tendon_length": float, "fibers": list}
_JOINT_KEYS = {"bones": list, "centre": list, "axis": list}


class AuthoringError(ValueError):
    """A parts file, surface or meshed part that cannot make a scene (the message names it and the fix)."""


@dataclass
class PartSpec:
    name: str
    surface: object                    # absolute path, or the surface itself: (V (n, 3), F (f, 3))
    kind: str                          # muscle | tendon | bone
    fixed: bool = True                 # bones
    tendon_length: float | None = None   # muscles
    fibers: list | None = None         # muscles: one direction


@dataclass
class JointSpec:
    bones: tuple
    centre: np.ndarray
    axis: np.ndarray | None = None


@dataclass
class PartsFile:
    path: str
    parts: list
    joints: list = field(default_factory=list)
    tets: int | None = None
    edge_length: float | None = None


@dataclass
class AuthoredScene:
    """What `author` made: the scene (parts with fibres, joints declared), the
    mesh's per-tet part ids (index into ``part_names``), and the report."""
    scene: Scene
    part_names: list
    part_kinds: list
    part: np.ndarray                   # (m,) part id per tet
    fiber: np.ndarray                  # (m, 3) unit fibre per tet (zero off the muscles)
    joints: list                       # [{"bones", "centre", "axis", "detected"}]
    report: dict


def _typed(table: dict, keys: dict, where: str) -> dict:
    for k, v in table.items():
        if k not in keys:
            raise AuthoringError(f"{where}: unknown key '{k}' (keys: {', '.join(keys)})")
        want = keys[k]
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) if want is float else isinstance(v, want)
        if not ok:
            raise AuthoringError(f"{where}.{k} must be a {want.__name__}, got {v!r}")
    return table


def _vector(v, where: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise AuthoringError(f"{where} must be three finite numbers, got {v!r}")
    return a


def read_parts(path) -> PartsFile:
    """Read and check a parts file (TOML); surfaces are resolved against its folder."""
    path = os.path.abspath(os.fspath(path))
    if not os.path.exists(path):
        raise FileNotFoundError(f"parts file not found: {path}")
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise AuthoringError(f"{path} is not valid TOML: {e}") from None
    unknown = set(data) - {"mesh", "part", "joint"}
    if unknown:
        raise AuthoringError(f"{path}: unknown table(s) {sorted(unknown)} (tables: [mesh], [[part]], [[joint]])")
    mesh = _typed(data.get("mesh", {}), {"tets": int, "edge_length": float}, "mesh")
    if "tets" in mesh and "edge_length" in mesh:
        raise AuthoringError("mesh: give tets or edge_length, not both")
    if "tets" in mesh and not mesh["tets"] >= 100:
        raise AuthoringError(f"mesh.tets must be at least 100, got {mesh['tets']}")
    if "edge_length" in mesh and not mesh["edge_length"] > 0:
        raise AuthoringError(f"mesh.edge_length must be positive, got {mesh['edge_length']}")
    folder = os.path.dirname(path)
    parts = []
    for i, p in enumerate(data.get("part", [])):
        parts.append(_part_spec(i, p, folder, {q.name for q in parts}))
    if not parts:
        raise AuthoringError(f"{path} lists no [[part]]")
    for kind in ("muscle", "bone"):
        if not any(p.kind == kind for p in parts):
            raise AuthoringError(f"{path}: no part is a {kind} (kind = \"{kind}\"); a scene needs muscles "
                                 "and the bones they attach to")
    bones = {p.name: p for p in parts if p.kind == "bone"}
    joints = [_joint_spec(i, j, bones) for i, j in enumerate(data.get("joint", []))]
    return PartsFile(path, parts, joints, mesh.get("tets"), mesh.get("edge_length"))


def _part_spec(i: int, p: dict, folder: str, names: set) -> PartSpec:
    """The i-th [[part]] checked (names: the parts before it)."""
    where = f"part {i + 1}" + (f" ('{p['name']}')" if isinstance(p.get("name"), str) else "")
    _typed(p, _PART_KEYS, where)
    for k in ("name", "surface", "kind"):
        if k not in p:
            raise AuthoringError(f"{where}: '{k}' is missing")
    name, kind = p["name"], p["kind"]
    if kind not in KINDS:
        raise AuthoringError(f"{where}: kind must be muscle, tendon or bone, got '{kind}'")
    if name in names:
        raise AuthoringError(f"{where}: a part named '{name}' exists already")
    if "fixed" in p and kind != "bone":
        raise AuthoringError(f"{where}: 'fixed' applies to bones only")
    for k in ("tendon_length", "fibers"):
        if k in p and kind != "muscle":
            raise AuthoringError(f"{where}: '{k}' applies to muscles only")
    if "tendon_length" in p and not p["tendon_length"] > 0:
        raise AuthoringError(f"{where}: tendon_length must be positive")
    fibers = None
    if "fibers" in p:
        fibers = _vector(p["fibers"], f"{where}.fibers")
        if np.linalg.norm(fibers) == 0:
            raise AuthoringError(f"{where}.fibers must not be zero")
        fibers = fibers.tolist()
    surface = os.path.join(folder, p["surface"])
    if not os.path.exists(surface):
        raise FileNotFoundError(f"{where}: surface file not found: {surface}")
    return PartSpec(name, surface, kind, bool(p.get("fixed", True)), p.get("tendon_length"), fibers)


def _joint_spec(i: int, j: dict, bones: dict) -> JointSpec:
    """The i-th [[joint]] checked against the parts file's bones."""
    where = f"joint {i + 1}"
    _typed(j, _JOINT_KEYS, where)
    if "bones" not in j or "centre" not in j:
        raise AuthoringError(f"{where}: 'bones' and 'centre' are required")
    pair = j["bones"]
    if len(pair) != 2 or pair[0] == pair[1] or not all(b in bones for b in pair):
        raise AuthoringError(f"{where}: bones must name two different bones (bones: {', '.join(bones) or 'none'})")
    if bones[pair[0]].fixed and bones[pair[1]].fixed:
        raise AuthoringError(f"{where}: both '{pair[0]}' and '{pair[1]}' are fixed; a joint needs a bone "
                             "with fixed = false")
    axis = None if "axis" not in j else _vector(j["axis"], f"{where}.axis")
    if axis is not None and np.linalg.norm(axis) == 0:
        raise AuthoringError(f"{where}.axis must not be zero")
    return JointSpec(tuple(pair), _vector(j["centre"], f"{where}.centre"), axis)


def read_surface(path) -> tuple:
    """A triangle surface (V (n, 3), F (f, 3)) from any file meshio reads (quads
    split in two), or from an ASCII VTK PolyData file (.vtp, OpenSim's geometry)."""
    import meshio

    if os.fspath(path).lower().endswith(".vtp"):
        from ..io.vtk import read_polydata
        try:
            return read_polydata(path)
        except ValueError as e:
            raise AuthoringError(str(e)) from None
    try:
        m = meshio.read(os.fspath(path))
    except (Exception, SystemExit) as e:  # meshio raises many types
        raise AuthoringError(f"could not read {path} as a surface ({type(e).__name__}: {e})") from None
    faces = []
    for c in m.cells:
        if c.type == "triangle":
            faces.append(np.asarray(c.data, np.int64))
        elif c.type == "quad":
            q = np.asarray(c.data, np.int64)
            faces += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
    if not faces:
        raise AuthoringError(f"{path} holds no triangles or quads (cell types: {sorted({c.type for c in m.cells})})")
    V = np.asarray(m.points, np.float64)[:, :3]
    if not np.all(np.isfinite(V)):
        raise AuthoringError(f"{path}: vertex coordinates contain NaN or inf")
    return V, np.concatenate(faces)


def surface_defects(F: np.ndarray) -> dict:
    """Edge counts of a triangle surface: {"open_edges": edges on one face,
    "nonmanifold_edges": edges on three or more}. A closed manifold has neither."""
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, count = np.unique(e, axis=0, return_counts=True)
    return {"open_edges": int(np.sum(count == 1)), "nonmanifold_edges": int(np.sum(count > 2))}


def self_intersections(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(k, 2) pairs of triangles of the surface (V, F) that cross each other
    (pairs sharing a vertex are not tested): a broad phase on a uniform grid of
    cells two mean edges wide, then an edge-triangle test both ways."""
    V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
    tri = V[F]
    edge = float(np.mean(np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1)))
    if not edge > 0:
        return np.zeros((0, 2), np.int64)
    lo = tri.min(axis=1)
    c0 = np.floor((lo - V.min(axis=0)) / (2 * edge)).astype(np.int64)
    c1 = np.floor((tri.max(axis=1) - V.min(axis=0)) / (2 * edge)).astype(np.int64)
    cells = {}
    for t in range(len(F)):
        for i in range(c0[t, 0], c1[t, 0] + 1):
            for j in range(c0[t, 1], c1[t, 1] + 1):
                for k in range(c0[t, 2], c1[t, 2] + 1):
                    cells.setdefault((i, j, k), []).append(t)
    pairs = set()
    for ts in cells.values():
        for x in range(len(ts)):
            for y in range(x + 1, len(ts)):
                pairs.add((ts[x], ts[y]))
    if not pairs:
        return np.zeros((0, 2), np.int64)
    P = np.array(sorted(pairs), np.int64)
    shared = (F[P[:, 0]][:, :, None] == F[P[:, 1]][:, None, :]).any(axis=(1, 2))
    P = P[~shared]
    hit = np.zeros(len(P), bool)
    for a, b in ((0, 1), (1, 0)):   # the edges of one triangle against the other
        T = tri[P[:, b]]
        for e0, e1 in ((0, 1), (1, 2), (2, 0)):
            hit |= _segment_hits_triangle(tri[P[:, a], e0], tri[P[:, a], e1], T)
    return P[hit]


def _segment_hits_triangle(p, q, T, eps: float = 1e-12) -> np.ndarray:
    """Whether segments p -> q (k, 3) cross triangles T (k, 3, 3) (Moller and
    Trumbore's ray-triangle test, kept to the segment, touching excluded)."""
    d = q - p
    e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    h = np.cross(d, e2)
    a = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(a) > eps * np.linalg.norm(d, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    s = p - T[:, 0]
    u = f * np.einsum("ij,ij->i", s, h)
    qv = np.cross(s, e1)
    v = f * np.einsum("ij,ij->i", d, qv)
    t = f * np.einsum("ij,ij->i", e2, qv)
    tol = 1e-9
    return ok & (u > tol) & (v > tol) & (u + v < 1 - tol) & (t > tol) & (t < 1 - tol)


def surface_volume(V: np.ndarray, F: np.ndarray) -> float:
    """The enclosed volume (divergence theorem; its sign tells the orientation)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def winding_numbers(V: np.ndarray, F: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Generalised winding numbers of points q (k, 3) about the surface (V, F):
    about 1 inside, 0 outside, also for surfaces with holes (Jacobson et al.
    2013: the sum of the triangles' signed solid angles over 4 pi, each by Van
    Oosterom and Strackee's formula)."""
    out = np.empty(len(q))
    for i in range(0, len(q), 256):
        a = V[F[:, 0]][None] - q[i:i + 256, None]
        b = V[F[:, 1]][None] - q[i:i + 256, None]
        c = V[F[:, 2]][None] - q[i:i + 256, None]
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("kfi,kfi->kf", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("kfi,kfi->kf", a, b) * lc + np.einsum("kfi,kfi->kf", a, c) * lb + \
            np.einsum("kfi,kfi->kf", b, c) * la
        out[i:i + 256] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return np.abs(out)


@contextlib.contextmanager
def _quiet_stdout():
    """fTetWild prints its progress to the C stdout: sent to /dev/null here."""
    import sys
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _mesher():
    try:
        from pytetwild import PyfTetWildWrapper
    except ImportError as e:
        raise ImportError("emu's mesher is fTetWild, from the package pytetwild, an optional extra: "
                          f"pip install 'emu[mesh]' (or 'pytetwild>=0.2.3,<0.3') [{e}]") from None
    return PyfTetWildWrapper


def tetrahedralize(surfaces: list, edge_length: float, *, quiet: bool = True, threads: int = 0,
                   epsilon: float = 1e-3) -> tuple:
    """ONE conforming tet mesh of the union of the closed surfaces [(V, F), ...],
    each tet labelled with the index of the last surface in the list that holds
    it (fTetWild's CSG union by winding numbers). epsilon: how far the mesh's
    boundary may stray from the surfaces, relative to their bounding-box
    diagonal (fTetWild's envelope; a tighter one refines near the surfaces).

    Returns points (n, 3), tets (m, 4) positively oriented, label (m,) in
    [0, len(surfaces)). Only the vertices the tets use are kept."""
    if len(surfaces) < 2:
        raise AuthoringError("tetrahedralize needs at least two surfaces (a muscle and a bone)")
    W = _mesher()
    lo = np.min([V.min(axis=0) for V, _ in surfaces], axis=0)
    hi = np.max([V.max(axis=0) for V, _ in surfaces], axis=0)
    diag = float(np.linalg.norm(hi - lo))
    with tempfile.TemporaryDirectory(prefix="emu_mesh_") as tmp:
        files = []
        for k, (V, F) in enumerate(surfaces):
            f = os.path.join(tmp, f"part{k}.obj")
            with open(f, "w") as out:
                np.savetxt(out, V, fmt="v %.17g %.17g %.17g")
                np.savetxt(out, F + 1, fmt="f %d %d %d")
            files.append(f)
        tree = files[0]
        for f in files[1:]:   # left-deep: fTetWild numbers the leaves 1, 2, ... in this order
            tree = {"operation": "union", "left": tree, "right": f}
        csg = os.path.join(tmp, "csg.json")
        with open(csg, "w") as out:
            json.dump(tree, out)
        with _quiet_stdout() if quiet else contextlib.nullcontext():
            v, c, marker = W.tetrahedralize_csg(csg, epsilon, edge_length / diag, 10.0, True, int(threads), 6, False)
    v, c, marker = np.asarray(v, np.float64), np.asarray(c, np.int64), np.asarray(marker, np.int64).ravel()
    if len(c) == 0:
        raise AuthoringError("the mesher returned no tets (are the surfaces closed and of a sensible size?)")
    used = np.unique(c)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    points, tets = v[used], remap[c]
    e1, e2, e3 = (points[tets[:, k]] - points[tets[:, 0]] for k in (1, 2, 3))
    neg = np.einsum("ij,ij->i", np.cross(e1, e2), e3) < 0
    tets[neg] = tets[neg][:, [0, 1, 3, 2]]
    return points, tets, marker - 1


def _tet_faces(tets: np.ndarray) -> tuple:
    """Faces shared by two tets: (faces (k, 3) vertex ids, tet_a (k,), tet_b (k,))."""
    f = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    owner = np.repeat(np.arange(len(tets)), 4)
    order = np.lexsort(f.T[::-1])
    f, owner = f[order], owner[order]
    same = np.all(f[1:] == f[:-1], axis=1)
    return f[1:][same], owner[:-1][same], owner[1:][same]


def _interface_areas(points, tets, part, n_parts) -> np.ndarray:
    """(n_parts, n_parts) areas of the faces between tets of two different parts."""
    faces, ta, tb = _tet_faces(tets)
    pa, pb = part[ta], part[tb]
    cross = pa != pb
    a, b, c = (points[faces[cross, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    out = np.zeros((n_parts, n_parts))
    np.add.at(out, (pa[cross], pb[cross]), area)
    return out + out.T


def _closest(pa: np.ndarray, pb: np.ndarray) -> tuple:
    """(distance, midpoint) of the closest pair of points between pa (k, 3) and pb (l, 3)."""
    best, mid = np.inf, None
    for i in range(0, len(pa), 1024):
        d2 = ((pa[i:i + 1024, None, :] - pb[None, :, :]) ** 2).sum(axis=2)
        k = np.unravel_index(np.argmin(d2), d2.shape)
        if d2[k] < best:
            best, mid = d2[k], 0.5 * (pa[i + k[0]] + pb[k[1]])
    return math.sqrt(best), mid


def _muscle_fibers(points, tets, muscle: str, mtets: np.ndarray, ends: dict) -> tuple:
    """Laplace fibres of a muscle (its tet ids mtets) between two of its ends
    ({neighbour part name: shared vertex ids}): the two ends farthest apart, or
    with one end from it to the muscle's far end. Returns (fibres (k, 3), note)."""
    sub = tets[mtets]
    if len(ends) >= 2:
        names = list(ends)
        cen = {n: points[ends[n]].mean(axis=0) for n in names}
        pairs = [(np.linalg.norm(cen[a] - cen[b]), a, b) for i, a in enumerate(names) for b in names[i + 1:]]
        _, a, b = max(pairs)
        origin, insertion = ends[a], np.setdiff1d(ends[b], ends[a])
        note = f"Laplace field from '{a}' to '{b}'"
    else:
        (a, origin), = ends.items()
        mv = np.unique(sub)
        d = np.linalg.norm(points[mv] - points[origin].mean(axis=0), axis=1)
        insertion = np.setdiff1d(mv[d >= FAR_END * d.max()], origin)
        note = f"Laplace field from '{a}' to the muscle's far end"
    if len(insertion) == 0:
        raise AuthoringError(f"muscle '{muscle}': its ends coincide; give it fibers = [x, y, z]")
    return laplace_fibers(points, sub, origin, insertion, fill_flat=True), note


def author(parts, *, quiet: bool = True, threads: int = 0, epsilon: float = 1e-3) -> AuthoredScene:
    """Mesh the parts' surfaces into one labelled tet mesh and build the
    Scene: parts with their kinds, attachments where muscles share vertices with
    bones, fibres, tendons, joints (declared, else detected). Raises
    AuthoringError naming the part and the fix for a part the mesher lost, a
    muscle attached to nothing, bones that touch, a surface that is not a
    volume.

    parts    a parts file (path), or a PartsFile whose PartSpecs may hold their
             surfaces as (V, F) arrays (emu.anatomy builds its scenes so)
    epsilon  the mesher's envelope (tetrahedralize)"""
    import time

    t0 = time.perf_counter()
    spec = parts if isinstance(parts, PartsFile) else read_parts(parts)
    surfaces, volumes, defects = [], [], []
    for p in spec.parts:
        if isinstance(p.surface, (str, os.PathLike)):
            V, F = read_surface(p.surface)
        else:
            V, F = (np.asarray(a) for a in p.surface)
        vol = surface_volume(V, F)
        d = surface_defects(F)
        crossing = self_intersections(V, F)
        if len(crossing):
            where = np.round(V[F[crossing[0, 0]]].mean(axis=0), 4).tolist()
            defects.append(f"part '{p.name}': its surface intersects itself ({len(crossing)} pair(s) of triangles "
                           f"cross, e.g. near {where}); meshed by winding numbers as it is: check the shape")
        if d["open_edges"] or d["nonmanifold_edges"]:
            defects.append(f"part '{p.name}': its surface is not closed "
                           f"({d['open_edges']} open edge(s), {d['nonmanifold_edges']} non-manifold); meshed by "
                           "winding numbers, which close small holes: check the part's shape")
        diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
        if not abs(vol) > 1e-9 * diag ** 3:
            raise AuthoringError(f"part '{p.name}': its surface encloses no volume (a flat or open "
                                 "sheet?); give a closed surface")
        surfaces.append((V, F))
        volumes.append(abs(vol))
    edge = spec.edge_length or (sum(volumes) / (TETS_PER_EDGE_CUBE * (spec.tets or 10000))) ** (1 / 3)
    order = sorted(range(len(spec.parts)), key=lambda i: _MESH_ORDER[spec.parts[i].kind])
    points, tets, label = tetrahedralize([surfaces[i] for i in order], edge, quiet=quiet, threads=threads,
                                         epsilon=epsilon)
    part = np.asarray(order)[label]
    mesh_s = time.perf_counter() - t0
    for i, p in enumerate(spec.parts):
        own = np.flatnonzero(part == i)
        if len(own) == 0:
            raise AuthoringError(f"part '{p.name}' was lost by the mesher: no tet lies in it (thinner than the "
                                 f"tet edge {edge:.3g}, or inside a part that wins overlaps: "
                                 f"{'bones' if p.kind != 'bone' else 'none'}); use a smaller edge_length or more tets")
        sample = own[np.linspace(0, len(own) - 1, min(len(own), 32)).astype(int)]
        inside = winding_numbers(*surfaces[i], points[tets[sample]].mean(axis=1)) > 0.5
        if inside.mean() < 0.5:
            raise AuthoringError(f"part '{p.name}': the mesher labelled tets outside its surface "
                                 f"({np.sum(~inside)} of {len(sample)} sampled); report this with the surfaces")
    defects += _soft_overlaps(spec, surfaces, points, tets, part, order)
    return _build_scene(spec, points, tets, part, edge, defects, mesh_s, t0)


def _soft_overlaps(spec: PartsFile, surfaces, points, tets, part, order) -> list:
    """Defects for soft parts of one kind that overlap each other (the rule gives
    overlap to bones, and a tendon overlapping a muscle takes the overlap: a
    tendon surface given as a part; between two muscles, or two tendons, the
    later in the parts file takes it, and that is reported):
    for each pair, the share of the winner's tets (a sample of up to
    OVERLAP_SAMPLE) that lie inside the loser's surface, reported above
    OVERLAP_REPORTED."""
    out = []
    rank = {i: k for k, i in enumerate(order)}
    soft = [i for i, p in enumerate(spec.parts) if p.kind != "bone"]
    for i in soft:
        for j in soft:
            if rank[j] <= rank[i] or spec.parts[i].kind != spec.parts[j].kind:
                continue   # j wins the overlap of i and j; a tendon over a muscle's end is meant
            own = np.flatnonzero(part == j)
            sample = own[np.linspace(0, len(own) - 1, min(len(own), OVERLAP_SAMPLE)).astype(int)]
            share = float(np.mean(winding_numbers(*surfaces[i], points[tets[sample]].mean(axis=1)) > 0.5))
            if share > OVERLAP_REPORTED:
                a, b = spec.parts[i].name, spec.parts[j].name
                out.append(f"parts '{a}' and '{b}' overlap: about {share:.0%} of '{b}' lies inside '{a}''s surface "
                           f"and went to '{b}' (soft parts overlap only by mistake: separate the surfaces)")
    return out


def _build_scene(spec: PartsFile, points, tets, part, edge, defects, mesh_s, t0) -> AuthoredScene:
    import time

    scene = Scene(points, tets)
    verts = [np.unique(tets[part == i]) for i in range(len(spec.parts))]
    for i, p in enumerate(spec.parts):   # bones and tendons first: the muscles' fibres run between them
        if p.kind == "bone":
            scene.add_bone(p.name, np.flatnonzero(part == i), fixed=p.fixed)
        elif p.kind == "tendon":
            scene.add_tendon(p.name, np.flatnonzero(part == i))
    fiber_notes = {p.name: _add_authored_muscle(scene, spec, i, points, tets, part, verts)
                   for i, p in enumerate(spec.parts) if p.kind == "muscle"}
    joints = _joints(spec, scene, points, tets, part, verts, edge)
    try:
        scene.validate()
    except ValueError as e:
        raise AuthoringError(f"the meshed scene cannot be solved: {e}") from None
    out_names = list(scene.parts)
    out_kinds = [scene.parts[n].kind for n in out_names]
    out_part = np.empty(len(tets), np.int64)
    fiber = np.zeros((len(tets), 3))
    for k, n in enumerate(out_names):
        p = scene.parts[n]
        out_part[p.tets] = k
        if p.kind == "muscle":
            fiber[p.tets] = p.fibers
    areas = _interface_areas(points, tets, out_part, len(out_names))
    attachments = [{"part": a, "bone": b, "area": float(areas[i, j])}
                   for i, a in enumerate(out_names) if out_kinds[i] != "bone"
                   for j, b in enumerate(out_names) if out_kinds[j] == "bone" and areas[i, j] > 0]
    defects += _sliver_defects(scene, out_names)
    report = {
        "tets": int(len(tets)), "vertices": int(len(points)), "edge_length": float(edge),
        "mesh_seconds": float(mesh_s), "seconds": float(time.perf_counter() - t0),
        "parts": [{"name": n, "kind": k, "tets": int(np.sum(out_part == i))}
                  for i, (n, k) in enumerate(zip(out_names, out_kinds))],
        "attachments": attachments, "joints": joints, "fibers": fiber_notes, "defects": defects,
        "free_bones": [b for b in scene.movable_bones
                       if not any(b in j["bones"] for j in joints)],
        "loop": (None if (pair := joint_loop(scene.joints(), scene.movable_bones)) is None else loop_note(pair)),
    }
    return AuthoredScene(scene, out_names, out_kinds, out_part, fiber, joints, report)


def _add_authored_muscle(scene: Scene, spec: PartsFile, i: int, points, tets, part, verts) -> str:
    """Part i, a muscle, into the scene with its fibres (given, or between the
    bones and tendons it touches) and its tendons; returns how its fibres were made."""
    p = spec.parts[i]
    idx = np.flatnonzero(part == i)
    ends = {q.name: np.intersect1d(verts[i], verts[j]) for j, q in enumerate(spec.parts)
            if j != i and q.kind in ("bone", "tendon")}
    ends = {k: v for k, v in ends.items() if len(v)}
    if not ends:
        raise AuthoringError(f"muscle '{p.name}' is attached to nothing: it neither overlaps nor touches a "
                             "bone or tendon; extend its surface into the bone it attaches to")
    if p.fibers is not None:
        fib, note = np.asarray(p.fibers, float), f"the direction {p.fibers}"
    else:
        fib, note = _muscle_fibers(points, tets, p.name, idx, ends)
    scene.add_muscle(p.name, idx, fib)
    if p.tendon_length is not None:
        try:
            scene.split_tendons(p.name, p.tendon_length)
        except ValueError as e:
            raise AuthoringError(f"part '{p.name}': {e}") from None
    return note


def _sliver_defects(scene: Scene, names: list) -> list:
    """A defect line per part with sliver tets."""
    out, slivers = [], scene.mesh_report.slivers
    for n in names:
        bad = np.intersect1d(slivers, scene.parts[n].tets)
        if len(bad):
            out.append(f"part '{n}': {len(bad)} sliver tet(s) (quality below 0.05, e.g. tet {bad[0]}): they "
                       "solve, but stiffen the part locally; a smaller edge_length usually removes them")
    return out


def _joints(spec: PartsFile, scene: Scene, points, tets, part, verts, edge) -> list:
    """Declare the parts file's joints on the scene, detect the others (see the
    module docstring); returns them as dicts {bones, centre, axis, detected, how}."""
    out = []
    for j in spec.joints:
        try:
            scene.add_joint(j.bones[0], j.bones[1], j.centre, j.axis)
        except ValueError as e:
            raise AuthoringError(f"joint {list(j.bones)}: {e}") from None
        out.append({"bones": list(j.bones), "centre": j.centre.tolist(),
                    "axis": None if j.axis is None else j.axis.tolist(), "detected": False, "how": "declared"})
    declared = {frozenset(j.bones) for j in spec.joints}
    bones = [i for i, p in enumerate(spec.parts) if p.kind == "bone"]
    for x, a in enumerate(bones):
        for b in bones[x + 1:]:
            pa, pb = spec.parts[a], spec.parts[b]
            if frozenset((pa.name, pb.name)) in declared or (pa.fixed and pb.fixed):
                continue
            shared = np.intersect1d(verts[a], verts[b])
            if len(shared) > 2:
                raise AuthoringError(
                    f"bones '{pa.name}' and '{pb.name}' touch in the mesh ({len(shared)} shared vertices), which "
                    f"welds them: leave a gap of about one tet edge ({edge:.3g}) between their surfaces; the joint "
                    "is then detected (a ball) or declare it ([[joint]] with centre and axis)")
            if len(shared):   # one or two shared vertices: emu.joints detects a ball or a hinge
                j = next(j for j in scene.joints() if set(j.bones) == {pa.name, pb.name})
                out.append({"bones": [pa.name, pb.name], "centre": np.asarray(j.centre).tolist(),
                            "axis": None if j.axis is None else np.asarray(j.axis).tolist(), "detected": True,
                            "how": f"{len(shared)} shared vertex(es)"})
                continue
            gap, mid = _closest(points[verts[a]], points[verts[b]])
            if gap <= JOINT_GAP * edge:
                first, second = (pb.name, pa.name) if pa.fixed else (pa.name, pb.name)
                scene.add_joint(first, second, mid, None)
                out.append({"bones": [first, second], "centre": mid.tolist(), "axis": None, "detected": True,
                            "how": f"surfaces {gap:.3g} apart"})
    return out


def write_authored(result: AuthoredScene, out_dir, *, frames: int = 20, dt: float = 0.05,
                   picture: bool = True) -> dict:
    """Write what `author` made into out_dir: mesh.vtu (cell data ``part``: the
    part id, ``fiber``: unit fibres, zero off the muscles), scene.json (the part
    ids' names and kinds, which emu.io.read takes from beside the mesh) and
    scene.toml (a scene file `emu info` and `emu run` accept as it is: movable
    bones, the joints, a default activation ramp per muscle to edit), report.json
    and, with picture, mesh.png (emu.io.plots.mesh_picture: the parts
    coloured, joints and attachments marked). Returns {name: path}."""
    from ..io.mesh import write

    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    paths = {k: os.path.join(out_dir, f) for k, f in
             (("mesh", "mesh.vtu"), ("parts", "scene.json"), ("scene", "scene.toml"), ("report", "report.json"),
              ("picture", "mesh.png"))}
    s = result.scene
    write(paths["mesh"], s.points, s.tets, cell_data={"part": result.part.astype(np.int32), "fiber": result.fiber})
    with open(paths["parts"], "w") as f:
        json.dump({"parts": [{"id": i, "name": n, "kind": k}
                             for i, (n, k) in enumerate(zip(result.part_names, result.part_kinds))]}, f, indent=1)
    with open(paths["report"], "w") as f:
        json.dump(result.report, f, indent=1)
    lines = ["# Made by `emu mesh`: edit the activations (and confirm the detected joints), then",
             f"#   emu run {paths['scene']} --out run",
             "[mesh]", 'path = "mesh.vtu"', 'fibers = "file"', "",
             "[solver]", 'method = "emu"', "accuracy = 0.01", "",
             "[frames]", f"count = {frames}", f"dt = {dt:g}", ""]
    for b in s.movable_bones:
        lines += [f"[bones.{_key(b)}]", "fixed = false", ""]
    for k, j in enumerate(result.joints):
        if j["how"].endswith("shared vertex(es)"):
            continue   # found again from the shared vertices
        lines += [f"[joints.joint{k + 1}]" + (f"   # detected ({j['how']}): confirm, or give an axis for a hinge"
                                               if j["detected"] else ""),
                  f"bones = [{', '.join(json.dumps(b) for b in j['bones'])}]",
                  f"centre = [{', '.join(f'{c:.9g}' for c in j['centre'])}]"]
        if j["axis"] is not None:
            lines.append(f"axis = [{', '.join(f'{c:.9g}' for c in j['axis'])}]")
        lines.append("")
    for n, k in zip(result.part_names, result.part_kinds):
        if k == "muscle":
            lines += [f"[activation.{_key(n)}]", "keys = [[0.0, 0.0], [%g, 0.3]]" % ((frames - 1) * dt),
                      'interpolation = "smooth"', "normalized = true", ""]
    with open(paths["scene"], "w") as f:
        f.write("\n".join(lines))
    if picture:
        mesh_picture(paths["picture"], s)
    else:
        del paths["picture"]
    return paths


def _key(name: str) -> str:
    """A TOML key for a part name (quoted unless bare)."""
    return name if name.replace("_", "").replace("-", "").isalnum() else json.dumps(name)


def format_report(report: dict) -> str:
    """The authoring report as text (what `emu mesh` prints)."""
    out = [f"{report['tets']} tets, {report['vertices']} vertices (tet edge {report['edge_length']:.3g}); "
           f"meshed in {report['mesh_seconds']:.1f} s"]
    for p in report["parts"]:
        out.append(f"  {p['kind']:6s} {p['name']}: {p['tets']} tets")
    for a in report["attachments"]:
        out.append(f"  attachment: {a['part']} on {a['bone']}, area {a['area']:.3g}")
    for j in report["joints"]:
        kind = "hinge" if j["axis"] is not None else "ball joint"
        out.append(f"  {kind} {' - '.join(j['bones'])} at {np.round(j['centre'], 4).tolist()} ({j['how']})"
                   + ("; confirm it in scene.toml" if j["detected"] else ""))
    for b in report["free_bones"]:
        out.append(f"  bone {b} has no joint: only its muscles hold it")
    for m, note in report["fibers"].items():
        out.append(f"  fibres of {m}: {note}")
    if report.get("loop"):
        out.append(f"  loop: {report['loop']}")
    out += [f"  defect: {d}" for d in report["defects"]]
    return "\n".join(out)
