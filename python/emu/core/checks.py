"""Input checks: the rest mesh (orientation, degenerate and sliver tets,
unused vertices) and the scene's connectivity (every piece anchored, no
welded movable bone).

Real meshes (TetWild, gmsh, the authors' research code) arrive with defects;
these checks report them, fix what has one right fix (vertex order), and
refuse what cannot be simulated (NaN, bad indices, zero-volume tets, pieces
nothing holds).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import _core
from .geometry import bbox_diagonal, boundary_faces

__all__ = ["MeshReport", "check_mesh", "tet_quality", "signed_volumes", "connected_components",
           "check_anchored", "check_movable_bones", "integer_ids", "inverted_tets", "coincident_vertices",
           "weld_coincident", "loose_contacts"]

SLIVER_QUALITY = 0.05
# Vertices closer than this x the bounding-box diagonal are one point (coincident_vertices).
COINCIDENT_TOL = 1e-9
# A soft part's surface lies on a bone where its vertices are within this x the
# median surface edge of the bone's surface (loose_contacts): separately meshed
# surfaces that touch differ by the chord sagitta, about h^2 / 8R << 0.05 h.
LOOSE_GAP = 0.05


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """points  (n, 3); tets  (m, 4) -> (m,) signed volumes."""
    p = points[tets]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0


def inverted_tets(tets, x) -> np.ndarray:
    """Indices of the tets (m, 4) whose deformed volume at positions x (n, 3) is
    not positive (det F <= 0 for positively oriented rest tets, which every
    emu.Scene has): inverted or collapsed."""
    return np.flatnonzero(signed_volumes(np.asarray(x, dtype=np.float64), np.asarray(tets)) <= 0.0)


def tet_quality(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Volume over RMS edge length cubed, scaled so a regular tet scores 1 (m,)."""
    p = points[tets]
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    l2 = np.mean([np.sum((p[:, a] - p[:, b]) ** 2, axis=1) for a, b in edges], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = 6.0 * np.sqrt(2.0) * np.abs(signed_volumes(points, tets)) / l2 ** 1.5
    return np.nan_to_num(q, nan=0.0)


@dataclass
class MeshReport:
    num_vertices: int
    num_tets: int
    reoriented: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # tet ids flipped
    slivers: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))     # quality < 0.05
    min_quality: float = 1.0
    unused_vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    # (k, 2) pairs of used vertices at the same position that no tet joins (cracks)
    coincident: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    def lines(self) -> list[str]:
        out = [f"{self.num_vertices} vertices, {self.num_tets} tets, min quality {self.min_quality:.3g}"]
        if len(self.reoriented):
            out.append(f"{len(self.reoriented)} tet(s) had negative volume (wrong vertex order) and were "
                       f"reoriented: {self.reoriented[:10].tolist()}")
        if len(self.slivers):
            out.append(f"{len(self.slivers)} sliver tet(s) with quality < {SLIVER_QUALITY}: "
                       f"{self.slivers[:10].tolist()} (they solve, but stiffen the mesh locally)")
        if len(self.unused_vertices):
            out.append(f"{len(self.unused_vertices)} vertex/vertices belong to no tet and are ignored")
        if len(self.coincident):
            a, b = self.coincident[0]
            out.append(f"{len(self.coincident)} pair(s) of vertices lie at the same point without being one vertex "
                       f"(e.g. {a} and {b}): a crack, as between parts meshed separately; nothing holds them "
                       "together. Weld them: load_scene(..., weld=True), --weld on the command line, or [mesh] "
                       "weld = true in a scene file")
        return out


def integer_ids(values, what: str) -> np.ndarray:
    """``values`` as int64 ids (any shape), or a ValueError naming ``what``:
    floats must be whole numbers (1.0 is 1; 0.5, NaN or inf are refused, never
    truncated), and anything else must be an integer array."""
    a = np.asarray(values)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        if a.size == 0:
            return a.astype(np.int64)
        raise ValueError(f"{what} must be integer ids, got an array of {a.dtype}")
    if np.issubdtype(a.dtype, np.floating) and a.size:
        if not np.all(np.isfinite(a)) or not np.all(a == np.round(a)):
            bad = a[~(np.isfinite(a) & (a == np.round(a)))].ravel()[0]
            raise ValueError(f"{what} must be whole numbers, got {bad}")
        if np.abs(a).max() >= 2**62:
            raise ValueError(f"{what} are out of range (largest {np.abs(a).max():g})")
    return a.astype(np.int64)


def _as_arrays(points, tets):
    try:
        points = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"points must be a numeric (n, 3) array: {e}") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {points.shape}")
    t = np.asarray(tets)
    if t.ndim != 2 or t.shape[1] != 4:
        raise ValueError(f"tets must have shape (m, 4), got {t.shape}")
    return points, integer_ids(t, "tets (vertex indices)")


def check_mesh(points, tets):
    """Validate and repair a rest mesh.

    points  (n, 3) rest positions;  tets  (m, 4) vertex indices.
    Returns (points, tets, report) with negative-volume tets reoriented.
    Raises ValueError for NaN/inf, out-of-range or repeated indices and
    zero-volume tets.
    """
    points, tets = _as_arrays(points, tets)
    n, m = len(points), len(tets)
    if n == 0 or m == 0:
        raise ValueError(f"the mesh is empty ({n} points, {m} tets)")
    if not np.all(np.isfinite(points)):
        bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
        raise ValueError(f"points contain NaN or inf at vertices {bad[:10].tolist()}; fix the mesh file")
    if tets.min() < 0 or tets.max() >= n:
        raise ValueError(f"tet indices must lie in [0, {n}), got range [{tets.min()}, {tets.max()}]"
                         " (1-based indices? subtract 1)")
    s = np.sort(tets, axis=1)
    rep = np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], axis=1))
    if len(rep):
        raise ValueError(f"{len(rep)} tet(s) repeat a vertex, e.g. tet {rep[0]} = {tets[rep[0]].tolist()}")
    vol = signed_volumes(points, tets)
    scale = bbox_diagonal(points) ** 3
    degenerate = np.flatnonzero(np.abs(vol) <= 1e-14 * scale)
    if len(degenerate):
        raise ValueError(f"{len(degenerate)} tet(s) have zero volume (e.g. tet {degenerate[0]}); remove them "
                         "or re-tetrahedralise")
    tets = tets.copy()
    neg = np.flatnonzero(vol < 0)
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    q = tet_quality(points, tets)
    used = np.zeros(n, bool)
    used[tets.ravel()] = True
    report = MeshReport(num_vertices=n, num_tets=m, reoriented=neg, slivers=np.flatnonzero(q < SLIVER_QUALITY),
                        min_quality=float(q.min()), unused_vertices=np.flatnonzero(~used),
                        coincident=coincident_vertices(points, tets))
    return points, tets, report


def coincident_vertices(points: np.ndarray, tets: np.ndarray, tol: float = COINCIDENT_TOL) -> np.ndarray:
    """(k, 2) pairs (a < b) of distinct vertices that tets use and that lie
    within tol x the bounding-box diagonal of each other (positions snapped to
    a grid of that spacing: exact duplicates, as separately meshed parts have
    on their common surface, always pair)."""
    used = np.unique(tets)
    h = tol * bbox_diagonal(points)
    key = np.round(points[used] / h).astype(np.int64) if h > 0 else points[used]
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    pairs = []
    for g in np.flatnonzero(counts > 1):
        ids = used[inverse == g]
        pairs += [(ids[0], other) for other in ids[1:]]
    return np.asarray(pairs, np.int64).reshape(-1, 2)


def weld_coincident(points: np.ndarray, tets: np.ndarray, tol: float = COINCIDENT_TOL) -> tuple:
    """Merge coincident vertices (coincident_vertices) into one and drop the
    vertices no tet uses. Returns (points (n', 3), tets (m, 4), old_to_new (n,)
    with -1 for dropped vertices). Vertex ids change: pin by name or after."""
    points, tets = np.asarray(points, np.float64), np.asarray(tets, np.int64)
    target = np.arange(len(points))
    for a, b in coincident_vertices(points, tets, tol):
        target[b] = target[a]
    tets = target[tets]
    keep = np.unique(tets)
    old_to_new = np.full(len(points), -1, np.int64)
    old_to_new[keep] = np.arange(len(keep))
    merged = old_to_new[target]
    merged[~np.isin(target, keep)] = -1
    return points[keep], old_to_new[tets], merged


def connected_components(num_vertices: int, tets: np.ndarray) -> np.ndarray:
    """Component label per vertex of the tet graph: the smallest vertex id of its
    piece (a vertex of no tet is its own piece).

    num_vertices  #V
    tets          (#T, 4) vertex ids in [0, #V)
    Returns (#V,) int64 labels (a union-find in the C++ core: one pass over the tets).
    """
    tets = np.asarray(tets).reshape(-1, 4)
    return _core.connected_components(int(num_vertices), tets.astype(np.int32, copy=False)).astype(np.int64)


# How to hold a piece, at each front door.
ANCHOR_FIX = ("attach it to a fixed bone (share vertices with it), pin it (scene file: pins = [\"{name}\"]; "
              "Python: scene.pin(ids)), or remove it")


def check_anchored(num_vertices: int, tets: np.ndarray, pinned: np.ndarray, links=(), anchors=(),
                   vertex_parts=None, bodies=()):
    """Raise ValueError unless every connected piece of the mesh made of ``tets``
    holds a pinned vertex.

    num_vertices  number of mesh vertices
    tets          (k, 4) the tets that carry unknowns (soft tets and movable bones)
    pinned        (p,) ids of the vertices the solve holds fixed
    links         (a, b) vertex-id pairs whose pieces count as one (a declared
                  joint between two movable bones)
    anchors       vertex ids whose piece counts as anchored (a declared joint to
                  a fixed bone)
    vertex_parts  optional callable: vertex ids -> the names of the parts they
                  belong to (the message then names the parts of a loose piece)
    bodies        vertex-id arrays, each moving as one rigid body (a movable
                  bone made of several shells, e.g. ulna + radius): their
                  pieces count as one
    """
    used = np.zeros(num_vertices, bool)
    used[tets.ravel()] = True
    pinned = np.asarray(pinned, np.int64)
    if not np.any(used[pinned]):
        raise ValueError("the scene is not anchored: nothing is pinned and no bone is fixed, so it can move "
                         "freely and no equilibrium is unique; fix a bone (scene file: [bones.<name>] fixed = "
                         "true; command line: leave it out of --free-bones), or pin vertices (scene file: pins = "
                         "[\"<part>\"]; Python: scene.pin(ids))")
    comp = connected_components(num_vertices, tets)
    merged = {c: c for c in np.unique(comp[used])}

    def root(c):
        while merged[c] != c:
            c = merged[c]
        return c
    links = list(links)
    for body in bodies:   # a rigid body's shells: one piece
        shells = np.unique(comp[np.asarray(body, np.int64)])
        first = np.flatnonzero(np.isin(comp, shells))
        reps = first[np.unique(comp[first], return_index=True)[1]]
        links += [(reps[0], r) for r in reps[1:]]
    for a, b in links:
        merged[root(comp[a])] = root(comp[b])
    lut = np.arange(comp.max() + 1)
    for c in merged:
        lut[c] = root(c)
    comp = lut[comp]
    anchored = np.unique(np.concatenate([comp[pinned[used[pinned]]],
                                         comp[np.asarray(list(anchors), dtype=np.int64)]]))
    loose = np.setdiff1d(np.unique(comp[used]), anchored)
    if len(loose):
        ids = np.flatnonzero(used)
        piece = ids[comp[ids] == loose[0]]
        if vertex_parts is not None:
            names = vertex_parts(piece)
            what = ", ".join(f"'{n}'" for n in names)
            raise ValueError(f"{what} {'is' if len(names) == 1 else 'are'} held by nothing (no pinned vertex, "
                             f"fixed bone or joint reaches {'it' if len(names) == 1 else 'them'}; {len(loose)} "
                             f"such piece(s), this one {len(piece)} vertices), so no equilibrium is unique: "
                             + ANCHOR_FIX.format(name=names[0]))
        raise ValueError(f"{len(loose)} connected piece(s) of the mesh have no pinned vertex (one has "
                         f"{len(piece)} vertices); pin a vertex of every piece")


def check_movable_bones(points: np.ndarray, bones: dict, held: np.ndarray):
    """Raise ValueError if a movable bone is held at three or more non-collinear
    vertices (a weld: it cannot move).

    points  (n, 3) rest positions
    bones   {movable bone name: its vertex ids}
    held    (p,) ids of the vertices the solve holds fixed (pins, fixed bones)
    """
    diag = bbox_diagonal(points)
    is_held = np.zeros(len(points), bool)
    is_held[np.asarray(held, np.int64)] = True
    for name, verts in bones.items():
        verts = np.asarray(verts, np.int64)
        on = np.unique(verts[is_held[verts]])   # the bone's held vertices, sorted (as np.intersect1d gives)
        if len(on) < 3:
            continue
        X = points[on] - points[on[0]]
        if np.linalg.svd(X, compute_uv=False)[1] > 1e-6 * diag:
            raise ValueError(f"movable bone '{name}' shares {len(on)} non-collinear vertices with pinned "
                             "vertices or fixed bones, so it cannot move (a weld); make it fixed=True, or "
                             "let it share one vertex (ball joint) or two (hinge)")


def loose_contacts(points: np.ndarray, tets: np.ndarray, soft: dict, bones: dict, *, shared_ok=(),
                   gap: float = LOOSE_GAP) -> list:
    """Where a soft part lies on a bone without sharing vertices with it: a
    muscle meshed apart from its bone (or non-conforming at the interface)
    touches it there but nothing attaches it.

    points     (n, 3) rest positions;  tets  (m, 4) vertex ids
    soft       {name: tet ids} muscles and tendons
    bones      {name: tet ids}
    shared_ok  vertex ids to count as shared (a crack's coincident vertices,
               reported on their own)
    gap        a vertex touches a surface within gap x its median edge length
    Returns [(soft name, bone name, faces, area)] for each pair where the soft
    part's surface triangles with all three vertices on the bone's surface
    (shared with it or within the gap) and not all shared cover more than two
    of its median triangles (less is a grazing triangle beside an attachment):
    their number and area.
    """
    points = np.asarray(points, np.float64)
    out = []
    ok = np.zeros(len(points), bool)
    ok[np.asarray(shared_ok, np.int64).ravel()] = True
    surfaces = {name: boundary_faces(tets[soft_tets]) for name, soft_tets in soft.items()}
    for bone, bone_tets in bones.items():
        bf = boundary_faces(tets[bone_tets])
        if len(bf) == 0:
            continue
        edges = np.linalg.norm(points[bf] - points[np.roll(bf, 1, axis=1)], axis=2)
        tol = gap * float(np.median(edges))
        on_bone = np.zeros(len(points), bool)
        on_bone[np.unique(tets[bone_tets])] = True
        for name, sf in surfaces.items():
            verts = np.unique(sf)
            query = verts[~on_bone[verts] & ~ok[verts]]
            if len(query) == 0:
                continue
            dist, _ = _core.near_surface(points, bf.astype(np.int32), points[query], tol)
            near = np.zeros(len(points), bool)
            near[query[np.isfinite(dist)]] = True
            loose = np.all(near[sf] | on_bone[sf] | ok[sf], axis=1) & np.any(near[sf], axis=1)
            if loose.any():
                p = points[sf]
                areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
                if areas[loose].sum() > 2.0 * np.median(areas):
                    out.append((name, bone, int(loose.sum()), float(areas[loose].sum())))
    return out
