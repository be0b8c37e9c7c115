"""Contact between the boundary surfaces of parts: IPC's smooth distance
barrier, its broad phase and continuous collision detection from ipctk (the
IPC toolkit; README, "Dependencies").

The energy, with d the distance between a surface point and a surface
triangle, or between two surface edges, of two parts that may touch:

    E_c(x) = kappa sum_c w_c b(d_c) / dhat,   b(d) = -(d - dhat)^2 ln(d / dhat)  for d < dhat

(w_c the area weight of the pair; the physical barrier's 1 / dhat makes E_c
an energy: kappa is a pressure). It grows without bound as d -> 0, so no
surface passes through another as long as every step is capped by
continuous collision detection, which the solver does. Contact pressure
about kappa dhat / d: the surfaces rest at a fraction of ``distance`` apart.

Scene.enable_contact stores a ContactSettings; the Solver builds a
ContactTerm (the FEM solver's PositionTerm in C++) from it. A scene without
contact builds nothing here and never imports ipctk.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..core.geometry import bbox_diagonal, boundary_faces

__all__ = ["ContactSettings", "ContactTerm", "ContactWarning", "DEFAULT_DISTANCE",
           "contact_available"]

# The barrier's reach (dhat) relative to the bounding-box diagonal by default
# (IPC's customary 1e-3 is below the gap a muscle mesh of a few thousand tets
# resolves; at 5e-3 the surfaces rest about a millimetre apart on a 0.3 m arm).
DEFAULT_DISTANCE = 5e-3
# ... and at most this fraction of the smallest rest gap between surfaces that
# may touch (non-adjacent elements: near an attachment, a muscle's surface and
# the bone's are one mesh edge apart), so that no barrier pushes at rest.
REST_GAP_FRACTION = 0.5


class ContactWarning(UserWarning):
    """Contact settings that make the barrier act in the rest state."""


def contact_available() -> bool:
    """Whether ipctk (the contact library) is installed."""
    try:
        import ipctk  # noqa: F401
    except ImportError:
        return False
    return True


def _ipctk():
    try:
        import ipctk
    except ImportError as e:
        raise ImportError("contact needs the ipctk package (the IPC toolkit): pip install ipctk, "
                          "or pip install emu[contact]") from e
    return ipctk


@dataclass
class ContactSettings:
    """What touches what (see Scene.enable_contact).

    pairs         list of (part, part) name pairs that may touch; None: every
                  pair of different parts except two bones
    self_contact  also a part's surface with itself (folds)
    distance      dhat, the barrier's reach in scene units (None: DEFAULT_DISTANCE
                  x the bounding-box diagonal)
    stiffness     kappa in Pa (None: the softest muscle's shear modulus)
    """
    pairs: list | None = None
    self_contact: bool = False
    distance: float | None = None
    stiffness: float | None = None


def _contact_surface(scene, names: list, pairs) -> tuple:
    """(faces (#F, 3) int32, part index per face) of the boundary faces of the
    parts that may touch."""
    faces, face_tet = boundary_faces(scene.tets, return_tets=True)
    faces = faces.astype(np.int32)
    owner = np.full(len(scene.tets), -1, np.int64)
    for i, p in enumerate(scene.parts.values()):
        owner[p.tets] = i
    face_part = owner[face_tet]
    touching = {names.index(a) for a, b in pairs} | {names.index(b) for a, b in pairs}
    keep = np.isin(face_part, sorted(touching))
    if not keep.any():
        raise ValueError("contact: the parts named have no boundary surface")
    return faces[keep], face_part[keep]


def _collision_vertex_parts(scene, names: list, faces, face_part, on_surface) -> np.ndarray:
    """The part of each collision vertex (the surface vertices in order): a
    vertex several parts share (an attachment) counts for its soft part, so a
    muscle's surface does not push against itself where it meets a bone; ipctk
    skips pairs of elements that share a vertex."""
    full_id = np.flatnonzero(on_surface)           # collision vertex -> scene vertex
    local = np.full(len(on_surface), -1, np.int64)
    local[full_id] = np.arange(len(full_id))
    soft_first = sorted(range(len(names)), key=lambda i: scene.parts[names[i]].kind == "bone")
    rank = np.empty(len(names), np.int64)
    rank[soft_first] = np.arange(len(names))
    vrank = np.full(len(full_id), len(names), np.int64)
    np.minimum.at(vrank, local[faces].ravel(), np.repeat(rank[face_part], 3))
    return np.asarray(soft_first)[vrank]


class ContactTerm:
    """The contact energy of a scene, for the solver (C++ calls energy,
    gradient, hessian and max_step with #V by 3 positions).

    Collision vertices carry the set of parts whose boundary faces they touch;
    two vertices may collide when the settings allow a pair of their parts and,
    without self-contact, they share no part (so a muscle's own surface near an
    attachment does not push against itself).
    """

    def __init__(self, scene, settings: ContactSettings):
        ipctk = _ipctk()
        self._ipctk = ipctk
        names = list(scene.parts)
        pairs = _allowed_pairs(scene, settings)
        self.faces, face_part = _contact_surface(scene, names, pairs)
        self.distance = float(settings.distance if settings.distance is not None
                              else DEFAULT_DISTANCE * bbox_diagonal(scene.points))
        self.stiffness = float(settings.stiffness if settings.stiffness is not None
                               else scene.reference_shear_modulus())
        for name, v in (("distance", self.distance), ("stiffness", self.stiffness)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"contact: {name} must be a positive number, got {v!r}")
        n = len(scene.points)
        on_surface = np.zeros(n, bool)
        on_surface[self.faces.ravel()] = True
        self.mesh = ipctk.CollisionMesh(on_surface.tolist(), np.zeros(n, bool).tolist(),
                                        np.asarray(scene.points, np.float64), ipctk.edges(self.faces), self.faces)
        self.vertex_part = _collision_vertex_parts(scene, names, self.faces, face_part, on_surface)
        allowed = np.zeros((len(names), len(names)), bool)
        for a, b in pairs:
            allowed[names.index(a), names.index(b)] = allowed[names.index(b), names.index(a)] = True
        self._install_filter(allowed)
        self.pairs = pairs
        self._set_distance(scene, settings)
        self.potential = ipctk.BarrierPotential(self.distance, self.stiffness, True)
        self.project = ipctk.PSDProjectionMethod.CLAMP   # tests switch it to NONE for finite differences
        self._key = None
        self._collisions = None
        self.evaluations = 0
        # seconds spent per kind of call (bench/studies/contact.py reports them)
        self.seconds = dict.fromkeys(("collisions", "energy", "gradient", "hessian", "ccd"), 0.0)

    def report(self, positions) -> dict:
        """Solution.contact at positions: the pairs within reach, the smallest gap, whether surfaces intersect."""
        return {"pairs": self.active_pairs(positions), "min_distance": self.minimum_distance(positions),
                "intersecting": self.intersecting(positions)}

    def _install_filter(self, allowed) -> None:
        """Which collision vertices may touch (allowed: part by part): no filter
        where every pair may, ipctk's patch filter where patches express it,
        else a Python filter (ipctk then on one thread)."""
        ipctk = self._ipctk
        present = np.unique(self.vertex_part)
        patch = _patches(allowed, present)
        self._python_filter = False
        if allowed[np.ix_(present, present)].all():
            return   # every pair, self-contact included: no filter
        if patch is None:
            # a Python filter: ipctk must then run on this thread (its worker
            # threads calling back into Python would wait for the GIL held here)
            vp = self.vertex_part
            self.mesh.can_collide = ipctk.CollisionFilter(lambda i, j: bool(allowed[vp[i], vp[j]]))
            self._python_filter = True
            # for the rest of the process, not per call: set back to more threads
            # between calls, a worker still awake from the last parallel call can take
            # a filter task and wait for the GIL forever (docs/DESIGN.md, "Contact")
            ipctk.set_num_threads(1)
        else:
            # pairs may touch exactly when their patches differ: ipctk's own filter
            self.mesh.can_collide = ipctk.make_vertex_patches_filter(patch[self.vertex_part].astype(np.int32))

    def _set_distance(self, scene, settings) -> None:
        """The barrier's reach within the smallest rest gap between surfaces that may
        touch: a default one is lowered to REST_GAP_FRACTION of it, a given one warned about."""
        gap = self._rest_gap(scene.points, self.distance)
        if gap < self.distance:
            if settings.distance is None:
                self.distance = REST_GAP_FRACTION * gap
            else:
                import warnings
                warnings.warn(ContactWarning(
                    f"contact distance {self.distance:.3g} exceeds the smallest rest gap between surfaces that "
                    f"may touch ({gap:.3g}, e.g. one mesh edge from an attachment): the barrier pushes in the "
                    f"rest state; a distance below {gap:.3g} avoids that"), stacklevel=4)
        if not self.distance > 0:
            raise ValueError("contact: surfaces that may touch already touch at rest (zero gap); leave "
                             "such pairs out (enable_contact(pairs=...))")
        self.rest_gap = gap

    def _rest_gap(self, points, reach) -> float:
        """The smallest distance between surface elements that may touch at rest,
        looked for within ``reach`` (inf if none is that close)."""
        V = self.surface_positions(points)
        c = self._ipctk.NormalCollisions()
        with self._broad_phase():
            c.build(self.mesh, V, reach)
        return float(np.sqrt(c.compute_minimum_distance(self.mesh, V))) if len(c) else float("inf")

    # --------------------------------------------------------------- geometry
    @contextmanager
    def _broad_phase(self):
        """A call that filters pairs: ipctk on one thread (set in __init__ and
        checked here, since something else may have raised it since)."""
        if self._python_filter and self._ipctk.get_num_threads() != 1:
            self._ipctk.set_num_threads(1)
        yield

    def surface_positions(self, x) -> np.ndarray:
        """The collision vertices' rows of x (#V by 3)."""
        return self.mesh.vertices(np.asarray(x, np.float64))

    def _at(self, x):
        """(collision vertices, active collisions) at x, cached for the last x."""
        V = self.surface_positions(x)
        key = V.tobytes()
        if key != self._key:
            t0 = time.perf_counter()
            c = self._ipctk.NormalCollisions()
            c.use_area_weighting = True
            with self._broad_phase():
                c.build(self.mesh, V, self.distance)
            self._key, self._collisions = key, c
            self.evaluations += 1
            self.seconds["collisions"] += time.perf_counter() - t0
        return V, self._collisions

    def minimum_distance(self, x) -> float:
        """The smallest distance between surfaces that may touch, at x (inf if
        none is within the barrier's reach)."""
        V, c = self._at(x)
        return float(np.sqrt(c.compute_minimum_distance(self.mesh, V))) if len(c) else float("inf")

    def intersecting(self, x) -> bool:
        """Whether any two surfaces that may touch intersect at x."""
        with self._broad_phase():
            return bool(self._ipctk.has_intersections(self.mesh, self.surface_positions(x)))

    def active_pairs(self, x) -> int:
        """Number of point-triangle and edge-edge pairs within the barrier's reach at x."""
        return len(self._at(x)[1])

    # ------------------------------------------------------- the solver's calls
    def check_start(self, x):
        """Raise ValueError if surfaces that may touch intersect at x (a solve's start)."""
        if self.intersecting(x):
            raise ValueError("contact: surfaces pass through each other at the start of the solve (a warm "
                             "start, pin targets or scripted bones placed into another part); move pins "
                             "and scripted bones in smaller steps between frames, or start from rest")

    def energy(self, x) -> float:
        V, c = self._at(x)
        t0 = time.perf_counter()
        e = float(self.potential(c, self.mesh, V)) if len(c) else 0.0
        self.seconds["energy"] += time.perf_counter() - t0
        return e

    def gradient(self, x) -> np.ndarray:
        V, c = self._at(x)
        n = self.mesh.full_num_vertices
        if not len(c):
            return np.zeros((n, 3))
        t0 = time.perf_counter()
        g = self.mesh.to_full_dof(self.potential.gradient(c, self.mesh, V)).reshape(n, 3)
        self.seconds["gradient"] += time.perf_counter() - t0
        return g

    def hessian(self, x):
        V, c = self._at(x)
        n3 = 3 * self.mesh.full_num_vertices
        if not len(c):
            import scipy.sparse as sp
            return sp.csc_matrix((n3, n3))
        t0 = time.perf_counter()
        H = self.mesh.to_full_dof(self.potential.hessian(c, self.mesh, V, project_hessian_to_psd=self.project))
        self.seconds["hessian"] += time.perf_counter() - t0
        return H

    def max_step(self, x0, x1) -> float:
        """The largest s in [0, 1] with the straight path x0 -> x0 + s (x1 - x0) free of crossings."""
        t0 = time.perf_counter()
        with self._broad_phase():
            s = float(self._ipctk.compute_collision_free_stepsize(
                self.mesh, self.surface_positions(x0), self.surface_positions(x1)))
        self.seconds["ccd"] += time.perf_counter() - t0
        return s


def _patches(allowed: np.ndarray, present: np.ndarray):
    """Patch ids per part such that two parts may touch exactly when their
    patches differ (parts that may not touch merged into one patch), or None
    where no such ids exist (a part pair list that is not of that form, or
    self-contact)."""
    n = len(allowed)
    patch = np.arange(n)
    for p in present:
        for q in present:
            if p != q and not allowed[p, q]:
                patch[patch == patch[q]] = patch[p]
    for p in present:
        for q in present:
            if allowed[p, q] != (patch[p] != patch[q]):
                return None
    return patch


def contact_settings(names, pairs, self_contact: bool, distance, stiffness) -> ContactSettings:
    """Scene.enable_contact's settings, checked (names: the scene's parts)."""
    if pairs is not None:
        pairs = check_pairs(names, pairs, self_contact, "enable_contact")
    for name, v in (("distance", distance), ("stiffness", stiffness)):
        if v is not None and not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            raise ValueError(f"enable_contact: {name} must be a positive number, got {v!r}")
    return ContactSettings(pairs=pairs, self_contact=bool(self_contact),
                           distance=None if distance is None else float(distance),
                           stiffness=None if stiffness is None else float(stiffness))


def check_pairs(names, pairs, self_contact: bool, where: str) -> list:
    """The pairs [(part, part)] as tuples; ValueError (prefixed ``where``) for a
    pair that is not two of ``names``, or a self pair without self_contact."""
    out = []
    for pair in pairs:
        if not isinstance(pair, (tuple, list)) or len(pair) != 2:
            raise ValueError(f"{where}: each pair names two parts, got {pair!r}")
        for name in pair:
            if name not in names:
                raise ValueError(f"{where}: no part named '{name}' (parts: {', '.join(names)})")
        if pair[0] == pair[1] and not self_contact:
            raise ValueError(f"{where}: the pair ({pair[0]!r}, {pair[1]!r}) is self-contact; pass self_contact=True")
        out.append(tuple(pair))
    return out


def _allowed_pairs(scene, settings: ContactSettings) -> list:
    names = list(scene.parts)
    if settings.pairs is None:
        pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]
                 if not (scene.parts[a].kind == "bone" and scene.parts[b].kind == "bone")]
        if settings.self_contact:
            pairs += [(a, a) for a in names if scene.parts[a].kind != "bone"]
    else:
        pairs = check_pairs(names, settings.pairs, settings.self_contact, "contact")
    if not pairs:
        raise ValueError("contact: no pair of parts can touch (the scene has one part, or bones only); "
                         "name pairs, or pass self_contact=True")
    return pairs
