"""The scene: one tet mesh, its labelled parts, materials and boundary conditions."""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from . import _core
from .checks import MeshReport, check_mesh, connected_components

__all__ = ["Scene", "Part", "lame", "MeshWarning"]


class MeshWarning(UserWarning):
    """A defect in the input mesh that emu repaired or that may affect results."""


def lame(youngs: float, poisson: float) -> tuple[float, float]:
    """(mu, lambda) from Young's modulus and Poisson ratio."""
    if not youngs > 0:
        raise ValueError(f"Young's modulus must be positive, got {youngs}")
    if not 0 < poisson < 0.5:
        raise ValueError(f"Poisson ratio must lie in (0, 0.5), got {poisson}")
    mu = youngs / (2.0 * (1.0 + poisson))
    lam = youngs * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    return mu, lam


# ACAP weight of movable bones' tets: the fitted bone positions follow the
# bone's rotation to about 1/weight of the soft tissue's pull (measured in
# docs/DESIGN.md); large weights only touch the small dense bone block.
BONE_ACAP_WEIGHT = 1e4


@dataclass
class Part:
    name: str
    kind: str               # "muscle" or "tendon"
    tets: np.ndarray        # tet ids
    youngs: float
    poisson: float
    density: float
    acap_weight: float
    fibers: np.ndarray | None = None   # (len(tets), 3) unit vectors, muscles only
    max_activation: float = 1e5        # a for normalised activation 1.0
    fixed: bool = True                 # bones: fixed (or scripted) rather than moved by the muscles
    joint_stiffness: float = 0.0       # movable bones: passive rotational stiffness (N m / rad)

    @property
    def mu(self) -> float:
        return lame(self.youngs, self.poisson)[0]


class Scene:
    """A musculoskeletal scene on one conforming tet mesh.

    points  (n, 3) rest positions; tets  (m, 4) vertex indices. Negative-volume
    tets are reoriented and slivers reported, both with a MeshWarning; the
    report stays in ``scene.mesh_report``.
    """

    def __init__(self, points, tets, *, warn: bool = True):
        self.points, self.tets, self.mesh_report = check_mesh(points, tets)
        if warn:
            for line in self.mesh_report.lines()[1:]:
                warnings.warn(line, MeshWarning, stacklevel=2)
        self.parts: dict[str, Part] = {}
        self._owner = np.full(len(self.tets), -1, np.int64)  # part index per tet
        self.pinned = np.zeros(0, np.int64)
        self.pin_targets = np.zeros((0, 3))
        self.gravity = np.zeros(3)
        self.declared_joints = []   # add_joint: {"bones", "kind", "centre", "axis"}

    # ----------------------------------------------------------------- parts
    def _tet_ids(self, name, tets) -> np.ndarray:
        idx = np.asarray(tets)
        if idx.dtype == bool:
            if idx.shape != (len(self.tets),):
                raise ValueError(f"part '{name}': a boolean tet mask must have shape ({len(self.tets)},), "
                                 f"got {idx.shape}")
            idx = np.flatnonzero(idx)
        idx = idx.astype(np.int64).ravel()
        if idx.size == 0:
            raise ValueError(f"part '{name}' has no tets")
        if idx.min() < 0 or idx.max() >= len(self.tets):
            raise ValueError(f"part '{name}': tet ids must lie in [0, {len(self.tets)}), got "
                             f"[{idx.min()}, {idx.max()}]")
        if len(np.unique(idx)) != len(idx):
            raise ValueError(f"part '{name}' lists some tets twice")
        taken = self._owner[idx] >= 0
        if taken.any():
            other = list(self.parts)[self._owner[idx[taken][0]]]
            raise ValueError(f"part '{name}': {taken.sum()} tet(s) already belong to part '{other}'")
        if name in self.parts:
            raise ValueError(f"a part named '{name}' exists already")
        return idx

    def _add(self, part: Part):
        self._owner[part.tets] = len(self.parts)
        self.parts[part.name] = part
        return part

    def add_muscle(self, name: str, tets, fibers=None, *, origin=None, insertion=None, youngs: float = 6e4,
                   poisson: float = 0.49, density: float = 1060.0, max_activation: float = 1e5,
                   acap_weight: float = 1.0) -> Part:
        """A contractile part.

        tets     tet ids (or a boolean mask over all tets)
        fibers   (len(tets), 3) fibre directions (normalised here) or one (3,) direction for all;
                 None: a Laplace field from ``origin`` to ``insertion`` (vertex ids), or, if those
                 are not given either, between the muscle's two bone attachments (resolved when
                 the scene is solved: add the bones first or later)
        max_activation  the activation a that a normalised activation of 1 means
        """
        idx = self._tet_ids(name, tets)
        lame(youngs, poisson)
        if not max_activation > 0:
            raise ValueError(f"muscle '{name}': max_activation must be positive")
        if fibers is None:
            if (origin is None) != (insertion is None):
                raise ValueError(f"muscle '{name}': give both origin and insertion vertex ids, or neither")
            f = None
            if origin is not None:
                from .fibers import laplace_fibers
                try:
                    f = laplace_fibers(self.points, self.tets[idx], origin, insertion)
                except ValueError as e:
                    raise ValueError(f"muscle '{name}': {e}") from None
            return self._add(Part(name, "muscle", idx, youngs, poisson, density, acap_weight, f, max_activation))
        f = np.asarray(fibers, dtype=np.float64)
        if f.shape == (3,):
            f = np.tile(f, (len(idx), 1))
        if f.shape != (len(idx), 3):
            raise ValueError(f"muscle '{name}': fibers must have shape ({len(idx)}, 3) or (3,), got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise ValueError(f"muscle '{name}': fibers contain NaN or inf")
        norm = np.linalg.norm(f, axis=1)
        if np.any(norm < 1e-12):
            raise ValueError(f"muscle '{name}': {np.sum(norm < 1e-12)} fibre direction(s) are zero")
        return self._add(Part(name, "muscle", idx, youngs, poisson, density, acap_weight, f / norm[:, None],
                              max_activation))

    def add_tendon(self, name: str, tets, *, youngs: float = 4.5e8, poisson: float = 0.49,
                   density: float = 1100.0, acap_weight: float | None = None) -> Part:
        """A stiff, never-activated soft part. acap_weight None: chosen from the stiffness
        ratio to the muscles (see Solver)."""
        idx = self._tet_ids(name, tets)
        lame(youngs, poisson)
        return self._add(Part(name, "tendon", idx, youngs, poisson, density,
                              acap_weight if acap_weight is not None else np.nan))

    def add_bone(self, name: str, tets, *, youngs: float = 1e10, poisson: float = 0.49,
                 density: float = 1900.0, fixed: bool = True, acap_weight: float = BONE_ACAP_WEIGHT,
                 joint_stiffness: float = 0.0) -> Part:
        """A bone: rigid. Muscle vertices it shares are attachments; vertices it
        shares with another bone are a joint (see joints()).

        fixed=True   the bone is prescribed: at rest, or scripted per solve
                     (Solver.solve(bone_poses=...)); its tets are left out of the solve.
        fixed=False  the muscles move it: a rigid body, turning about its joints with
                     fixed bones (one shared vertex: ball joint, two: hinge) or free
                     if it has none. Its density counts under gravity.
        acap_weight  EMU's ACAP weight on the bone's tets (movable bones): the larger,
                     the closer the fitted positions follow the bone's rotation.
        joint_stiffness  movable bones: a passive spring k (N m / rad) against turning
                     away from the rest pose, energy k (1 - cos theta) ~ k theta^2 / 2
                     (ligaments; it also removes neutral modes a lone muscle leaves).
        """
        idx = self._tet_ids(name, tets)
        lame(youngs, poisson)
        if not acap_weight > 0:
            raise ValueError(f"bone '{name}': acap_weight must be positive, got {acap_weight!r}")
        if not (np.isfinite(joint_stiffness) and joint_stiffness >= 0):
            raise ValueError(f"bone '{name}': joint_stiffness must be >= 0, got {joint_stiffness!r}")
        return self._add(Part(name, "bone", idx, youngs, poisson, density, float(acap_weight), fixed=bool(fixed),
                              joint_stiffness=float(joint_stiffness)))

    @property
    def movable_bones(self) -> list:
        """Names of the bones the muscles move (fixed=False), in the solver's order."""
        return [p.name for p in self.parts.values() if p.kind == "bone" and not p.fixed]

    def attachments(self, muscle: str) -> dict:
        """{bone name: vertex ids} where the muscle shares vertices with a bone."""
        from .fibers import attachments

        p = self._part(muscle, "muscle")
        return attachments(self.tets, p.tets, {b.name: b.tets for b in self.parts.values() if b.kind == "bone"})

    def joints(self) -> list:
        """Joints detected from vertices shared by two bones: one shared vertex is
        a ball joint (``centre``), two or more on one line a hinge (``axis``
        through ``centre``), more not on a line a rigid weld. Returns dicts with
        bones, kind, vertices, centre, axis."""
        bones = [p for p in self.parts.values() if p.kind == "bone"]
        verts = {b.name: np.unique(self.tets[b.tets].ravel()) for b in bones}
        out = []
        for i, a in enumerate(bones):
            for b in bones[i + 1:]:
                shared = np.intersect1d(verts[a.name], verts[b.name])
                if len(shared) == 0:
                    continue
                p = self.points[shared]
                kind, axis = _joint_kind(p, self.points)
                out.append({"bones": (a.name, b.name), "kind": kind, "vertices": shared,
                            "centre": p.mean(axis=0), "axis": axis, "declared": False})
        for j in self.declared_joints:
            out.append(dict(j, vertices=np.zeros(0, np.int64), declared=True))
        return out

    def add_joint(self, bone: str, other: str, centre, axis=None) -> dict:
        """Declare a joint between two bones that share no vertex there (meshes
        whose bones do not touch): a ball joint at ``centre``, or with ``axis`` a
        hinge about the line through ``centre``. At least one of the bones must
        be movable (fixed=False); the other may be fixed or scripted."""
        for name in (bone, other):
            p = self.parts.get(name)
            if p is None or p.kind != "bone":
                known = [q.name for q in self.parts.values() if q.kind == "bone"]
                raise ValueError(f"add_joint: no bone named {name!r} (bones: {', '.join(known) or 'none'}); "
                                 "add the bones first")
        if bone == other:
            raise ValueError(f"add_joint: a joint needs two different bones, got {bone!r} twice")
        c = np.asarray(centre, dtype=np.float64)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f"add_joint: centre must be a finite 3-vector, got {centre!r}")
        a = None
        if axis is not None:
            a = np.asarray(axis, dtype=np.float64)
            if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
                raise ValueError(f"add_joint: axis must be a non-zero finite 3-vector, got {axis!r}")
            a = a / np.linalg.norm(a)
        j = {"bones": (bone, other), "kind": "ball" if a is None else "hinge", "centre": c, "axis": a}
        self.declared_joints.append(j)
        return j

    def split_tendons(self, muscle: str, distance: float, *, name: str | None = None, **tendon_options) -> Part:
        """Move the muscle's tets whose centroid lies within ``distance`` of one of
        its bone attachments into a new tendon part (default name "<muscle>_tendon");
        tendon_options go to add_tendon (youngs, poisson, density, acap_weight)."""
        p = self._part(muscle, "muscle")
        if not distance > 0:
            raise ValueError(f"split_tendons: distance must be positive, got {distance}")
        att = self.attachments(muscle)
        if not att:
            raise ValueError(f"muscle '{muscle}' shares no vertex with a bone: there is no attachment to "
                             "measure from; label the tendon tets yourself (add_tendon)")
        if p.fibers is None and len(att) == 2:
            # fibres run between the bone attachments, which the split hides behind the tendons
            self._fibers_between(p, att)
        anchor = self.points[np.unique(np.concatenate(list(att.values())))]
        c = self.points[self.tets[p.tets]].mean(axis=1)
        near = np.zeros(len(c), bool)
        for i in range(0, len(c), 4096):  # chunked: (chunk x attachments) distances
            d2 = ((c[i:i + 4096, None, :] - anchor[None, :, :]) ** 2).sum(axis=2)
            near[i:i + 4096] = d2.min(axis=1) <= distance * distance
        if near.all():
            raise ValueError(f"split_tendons: every tet of '{muscle}' lies within {distance} of an attachment; "
                             "use a smaller distance")
        if not near.any():
            raise ValueError(f"split_tendons: no tet of '{muscle}' lies within {distance} of an attachment")
        tendon_tets = p.tets[near]
        self._owner[tendon_tets] = -1
        p.tets = p.tets[~near]
        if p.fibers is not None:
            p.fibers = p.fibers[~near]
        return self.add_tendon(name or f"{muscle}_tendon", tendon_tets, **tendon_options)

    def _part(self, name: str, kind: str | None = None) -> Part:
        if name not in self.parts:
            raise ValueError(f"no part named '{name}' (parts: {', '.join(self.parts) or 'none'})")
        p = self.parts[name]
        if kind is not None and p.kind != kind:
            raise ValueError(f"part '{name}' is a {p.kind}, not a {kind}")
        return p

    # ------------------------------------------------------ boundary conditions
    def pin(self, vertex_ids, positions=None):
        """Fix vertices at their rest positions (or at ``positions``, (k, 3))."""
        ids = np.asarray(vertex_ids).astype(np.int64).ravel()
        if ids.size == 0:
            raise ValueError("pin: no vertex ids given")
        if ids.min() < 0 or ids.max() >= len(self.points):
            raise ValueError(f"pin: vertex ids must lie in [0, {len(self.points)}), got [{ids.min()}, {ids.max()}]")
        pos = self.points[ids] if positions is None else np.asarray(positions, dtype=np.float64)
        if pos.shape != (len(ids), 3):
            raise ValueError(f"pin: positions must have shape ({len(ids)}, 3), got {pos.shape}")
        if not np.all(np.isfinite(pos)):
            raise ValueError("pin: positions contain NaN or inf")
        targets = dict(zip(self.pinned.tolist(), self.pin_targets))
        targets.update(zip(ids.tolist(), pos))
        self.pinned = np.array(sorted(targets), dtype=np.int64)
        self.pin_targets = np.array([targets[i] for i in self.pinned]).reshape(-1, 3)

    # ------------------------------------------------------------ model build
    @property
    def muscles(self) -> list[str]:
        return [p.name for p in self.parts.values() if p.kind == "muscle"]

    def reference_shear_modulus(self) -> float:
        """mu of the softest muscle (softest part if there is none): alpha's unit."""
        kinds = ([p for p in self.parts.values() if p.kind == "muscle"]
                 or [p for p in self.parts.values() if p.kind != "bone"])
        if not kinds:
            raise ValueError("the scene has no parts; add muscles or tendons first")
        return min(p.mu for p in kinds)

    @property
    def model_tets(self) -> np.ndarray:
        """Ids of the tets that carry unknowns (all but those of fixed bones)."""
        bone = np.zeros(len(self.tets), bool)
        for p in self.parts.values():
            if p.kind == "bone" and p.fixed:
                bone[p.tets] = True
        return np.flatnonzero(~bone)

    def model_pins(self) -> tuple[np.ndarray, np.ndarray]:
        """(ids, targets) of every vertex the solve holds fixed: the user's pins,
        vertices of fixed bones (at rest), and vertices of no soft tet."""
        used = np.zeros(len(self.points), bool)
        used[self.tets[self.model_tets].ravel()] = True
        fixed = ~used
        fixed[self.pinned] = True
        for p in self.parts.values():
            if p.kind == "bone" and p.fixed:
                fixed[self.tets[p.tets].ravel()] = True
        ids = np.flatnonzero(fixed)
        pos = self.points[ids].copy()
        where = np.searchsorted(ids, self.pinned)
        pos[where] = self.pin_targets
        return ids, pos

    def resolve_fibers(self):
        """Give every muscle without fibres a Laplace field between its two bone attachments."""
        for p in self.parts.values():
            if p.kind != "muscle" or p.fibers is not None:
                continue
            att = self.attachments(p.name)
            if len(att) != 2:
                found = ", ".join(f"{k} ({len(v)} vertices)" for k, v in att.items()) or "none"
                raise ValueError(f"muscle '{p.name}' has no fibres and {len(att)} bone attachment(s) ({found}); "
                                 "fibres from attachments need exactly two: pass fibers=, or origin= and "
                                 "insertion= vertex ids")
            self._fibers_between(p, att)

    def _fibers_between(self, part: Part, att: dict):
        """Laplace fibres of a muscle from its first attachment to its second."""
        from .fibers import laplace_fibers

        (_, origin), (_, insertion) = att.items()
        part.fibers = laplace_fibers(self.points, self.tets[part.tets], origin, insertion)

    def validate(self):
        if not self.parts:
            raise ValueError("the scene has no parts: add_muscle/add_tendon first")
        free = np.flatnonzero(self._owner < 0)
        if len(free):
            raise ValueError(f"{len(free)} tet(s) belong to no part (e.g. tet {free[0]}); add them to a "
                             "muscle, tendon or bone")
        soft = self.model_tets
        movable = [p for p in self.parts.values() if p.kind == "bone" and not p.fixed]
        if len(soft) == sum(len(p.tets) for p in movable):
            raise ValueError("the scene has no muscle or tendon tets: nothing to simulate")
        used = np.zeros(len(self.points), bool)
        used[self.tets[soft].ravel()] = True
        pins, _ = self.model_pins()
        if not np.any(used[pins]):
            raise ValueError("the scene is not anchored: pin some vertices (scene.pin) or attach the muscles "
                             "to a fixed bone; without an anchor no equilibrium is unique")
        comp = connected_components(len(self.points), self.tets[soft])
        # declared joints connect their bones' pieces (or anchor them, to a fixed bone)
        movable = set(self.movable_bones)
        piece = {p.name: comp[self.tets[p.tets[0], 0]] for p in self.parts.values()
                 if p.kind == "bone" and p.name in movable}
        merged = {c: c for c in np.unique(comp[used])}

        def root(c):
            while merged[c] != c:
                c = merged[c]
            return c
        extra_anchored = []
        for j in self.declared_joints:
            a, b = j["bones"]
            if a in piece and b in piece:
                merged[root(piece[a])] = root(piece[b])
            elif a in piece or b in piece:
                extra_anchored.append(piece[a] if a in piece else piece[b])
        lut = np.arange(comp.max() + 1)
        for c in merged:
            lut[c] = root(c)
        comp = lut[comp]
        anchored = np.unique(np.concatenate([comp[pins[used[pins]]],
                                             np.array([root(c) for c in extra_anchored], dtype=comp.dtype)]))
        loose = np.setdiff1d(np.unique(comp[used]), anchored)
        if len(loose):
            size = int(np.sum(comp[used] == loose[0]))
            raise ValueError(f"{len(loose)} connected piece(s) of the mesh have no pinned vertex (one has "
                             f"{size} vertices); pin a vertex of every piece")
        self._check_movable_bones(pins)
        if not np.all(np.isfinite(self.gravity)) or np.shape(self.gravity) != (3,):
            raise ValueError(f"gravity must be a finite 3-vector, got {self.gravity!r}")

    def _check_movable_bones(self, pins):
        """A movable bone held at three or more non-collinear vertices cannot move."""
        diag = float(np.linalg.norm(self.points.max(0) - self.points.min(0)))
        for p in self.parts.values():
            if p.kind != "bone" or p.fixed:
                continue
            held = np.intersect1d(np.unique(self.tets[p.tets].ravel()), pins)
            if len(held) < 3:
                continue
            X = self.points[held] - self.points[held[0]]
            if np.linalg.svd(X, compute_uv=False)[1] > 1e-6 * diag:
                raise ValueError(f"movable bone '{p.name}' shares {len(held)} non-collinear vertices with pinned "
                                 "vertices or fixed bones, so it cannot move (a weld); make it fixed=True, or "
                                 "let it share one vertex (ball joint) or two (hinge)")

    def acap_weight_of(self, part: Part) -> float:
        """The ACAP weight of a part (tendons without an explicit weight: default_tendon_weight)."""
        if not np.isnan(part.acap_weight):
            return part.acap_weight
        return default_tendon_weight(part.mu / self.reference_shear_modulus())

    def build_model(self) -> "_core.Model":
        """The flat arrays the C++ solvers take (tets of fixed bones left out)."""
        self.validate()
        self.resolve_fibers()
        keep = self.model_tets
        m = len(self.tets)
        mu, lam, rho, w = (np.empty(m) for _ in range(4))
        fib = np.zeros((m, 3))
        muscle = np.full(m, -1, np.int32)
        bone = np.full(m, -1, np.int32)
        names = self.muscles
        movable = self.movable_bones
        for p in self.parts.values():
            if p.kind == "bone" and not p.fixed:
                bone[p.tets] = movable.index(p.name)
            pm, pl = lame(p.youngs, p.poisson)
            mu[p.tets], lam[p.tets], rho[p.tets] = pm, pl, p.density
            w[p.tets] = self.acap_weight_of(p)
            if p.kind == "muscle":
                fib[p.tets] = p.fibers
                muscle[p.tets] = names.index(p.name)
        model = _core.Model()
        model.rest = self.points
        model.tets = self.tets[keep].astype(np.int32)
        model.mu, model.lam, model.density, model.acap_weight = mu[keep], lam[keep], rho[keep], w[keep]
        model.fiber = fib[keep]
        model.muscle = muscle[keep]
        model.pinned = self.model_pins()[0].astype(np.int32)
        model.num_muscles = len(names)
        if movable:
            model.bone = bone[keep]
            model.num_bones = len(movable)
            k = np.array([self.parts[n].joint_stiffness for n in movable], float)
            if np.any(k > 0):
                model.bone_stiffness = k
        pts, pairs = self._declared_joint_rows()
        if len(pts):
            model.joint_points = pts
            model.joint_bones = pairs.astype(np.int32)
        return model

    def _declared_joint_rows(self):
        """Rest points (#rows, 3) and (movable bone, other movable bone or -1) of
        the declared joints: one row per ball joint, two per hinge."""
        movable = self.movable_bones
        diag = float(np.linalg.norm(self.points.max(0) - self.points.min(0)))
        pts, pairs = [], []
        for j in self.declared_joints:
            a, b = j["bones"]
            if a not in movable:
                a, b = b, a
            if a not in movable:
                raise ValueError(f"joint {j['bones']}: both bones are fixed; make one of them movable "
                                 "(fixed=False) or drop the joint")
            ib = movable.index(b) if b in movable else -1
            rows = [j["centre"]] if j["axis"] is None else [j["centre"] - 0.1 * diag * j["axis"],
                                                           j["centre"] + 0.1 * diag * j["axis"]]
            for p in rows:
                pts.append(p)
                pairs.append((movable.index(a), ib))
        return np.asarray(pts, float).reshape(-1, 3), np.asarray(pairs, np.int64).reshape(-1, 2)

    def declared_joint_world(self):
        """(row, world bone name) of every declared-joint row tied to a fixed bone."""
        movable = self.movable_bones
        out, row = [], 0
        for j in self.declared_joints:
            a, b = j["bones"]
            if a not in movable:
                a, b = b, a
            n = 1 if j["axis"] is None else 2
            if b not in movable:
                out += [(row + i, b) for i in range(n)]
            row += n
        return out

    def __repr__(self):
        parts = ", ".join(f"{p.name} ({p.kind}, {len(p.tets)} tets)" for p in self.parts.values())
        return f"Scene({len(self.points)} vertices, {len(self.tets)} tets; {parts}; {len(self.pinned)} pinned)"


def _joint_kind(p: np.ndarray, all_points: np.ndarray) -> tuple:
    """("ball" | "hinge" | "weld", unit axis or None) of shared joint vertices p."""
    diag = float(np.linalg.norm(all_points.max(0) - all_points.min(0)))
    if len(p) == 1:
        return "ball", None
    c = p - p.mean(axis=0)
    _, sv, vt = np.linalg.svd(c, full_matrices=False)
    if len(sv) > 1 and sv[1] > 1e-6 * diag:
        return "weld", None
    return "hinge", vt[0] * (1.0 if vt[0][np.argmax(np.abs(vt[0]))] > 0 else -1.0)


def default_tendon_weight(stiffness_ratio: float) -> float:
    """ACAP weight for a part `stiffness_ratio` times stiffer than the muscles."""
    return float(min(max(stiffness_ratio, 1.0), 1e3) ** 0.5)
