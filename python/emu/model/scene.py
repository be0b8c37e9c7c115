"""The scene: one tet mesh, its labelled parts, materials and boundary
conditions (bookkeeping only: joints are found in emu.joints, input checks live
in emu.checks, and emu.lowering turns a scene into the C++ model)."""
from __future__ import annotations

import warnings

import numpy as np

from ..core.checks import check_mesh
from .contact import ContactSettings, contact_settings
from ..core.fibers import attachment_fibers, attachments
from .joints import declare_joint, detect_joints
from . import scene_checks, tendons
from .parts import BONE_ACAP_WEIGHT, Part, default_tendon_weight, lame, muscle_fibers, part_tet_ids

__all__ = ["Scene", "Part", "lame", "MeshWarning"]


class MeshWarning(UserWarning):
    """A defect in the input mesh that emu repaired or that may affect results."""


class Scene:
    """A musculoskeletal scene on one conforming tet mesh.

    points  (n, 3) rest positions; tets  (m, 4) vertex indices. Negative-volume
    tets are reoriented and slivers reported, both with a MeshWarning; the
    report stays in ``scene.mesh_report``.

    vertex_sets  {name: vertex ids} named vertex sets of a built-in scene (the
                 fusiform muscle's "proximal" and "distal" end faces), which
                 scene files can pin by name
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
        self.declared_joints = []   # Joint(declared=True) from add_joint
        self.vertex_sets: dict[str, np.ndarray] = {}
        self.contact: ContactSettings | None = None   # enable_contact

    # ----------------------------------------------------------------- parts
    def _tet_ids(self, name, tets) -> np.ndarray:
        return part_tet_ids(name, tets, self._owner, list(self.parts))

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
        f = muscle_fibers(self.points, self.tets[idx], name, fibers, origin, insertion)
        return self._add(Part(name, "muscle", idx, youngs, poisson, density, acap_weight, f, max_activation))

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
        p = self._part(muscle, "muscle")
        return attachments(self.tets, p.tets, self.bone_tets())

    def tendon_attachments(self, muscle: str) -> dict:
        """{bone name: (tendon name, vertex ids)} where a tendon sharing
        vertices with the muscle shares vertices with a bone: the muscle's
        attachments through its tendons (emu mesh's tendon_length puts them
        there)."""
        return tendons.tendon_attachments(self, muscle)

    def bone_tets(self) -> dict:
        """{bone name: tet ids} in the scene's order."""
        return {p.name: p.tets for p in self.parts.values() if p.kind == "bone"}

    def cracks(self) -> list:
        """[(part, other part, pairs)]: parts that touch at vertices lying at the
        same point without being shared (mesh_report.coincident), so that nothing
        holds them together there (a muscle meshed apart from its bone is not
        attached). Weld the mesh (emu.checks.weld_coincident, load_scene(...,
        weld=True)) to join them."""
        return scene_checks.cracks(self)

    def loose_contacts(self) -> list:
        """[(muscle or tendon, bone, triangles, area)]: where a soft part's surface
        lies on a bone's surface without sharing vertices with it (meshed apart,
        or non-conforming at the interface), so nothing attaches it there; a
        crack's coincident vertices are left to cracks(). Mesh the parts as one
        (emu mesh) where it should be attached; turn contact on where it slides."""
        return scene_checks.loose_contacts(self)

    def joints(self) -> list:
        """Joints (emu.joints.Joint) between bones: detected from vertices shared
        by two bones (one shared vertex is a ball joint at ``centre``, two or more
        on one line a hinge with ``axis`` through ``centre``, more not on a line a
        rigid weld), then the declared ones (add_joint)."""
        return detect_joints(self.points, self.tets, self.bone_tets()) + list(self.declared_joints)

    def add_joint(self, bone: str, other: str, centre, axis=None):
        """Declare a joint between two bones that share no vertex there (meshes
        whose bones do not touch): a ball joint at ``centre`` (3,), or with
        ``axis`` (3,) a hinge about the line through ``centre``. At least one of
        the bones must be movable (fixed=False); the other may be fixed or
        scripted. Returns the Joint."""
        j = declare_joint(self.bone_tets(), bone, other, centre, axis)
        self.declared_joints.append(j)
        return j

    def split_tendons(self, muscle: str, distance: float, *, name: str | None = None, **tendon_options) -> Part:
        """Move the muscle's tets whose centroid lies within ``distance`` of one of
        its bone attachments into a new tendon part (default name "<muscle>_tendon");
        tendon_options go to add_tendon (youngs, poisson, density, acap_weight)."""
        near = tendons.tets_near_attachments(self, muscle, distance)
        p = self._part(muscle, "muscle")
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
        ids, pos = scene_checks.pin_targets(self.points, vertex_ids, positions)
        targets = dict(zip(self.pinned.tolist(), self.pin_targets))
        targets.update(zip(ids.tolist(), pos))
        self.pinned = np.array(sorted(targets), dtype=np.int64)
        self.pin_targets = np.array([targets[i] for i in self.pinned]).reshape(-1, 3)

    def enable_contact(self, pairs=None, *, self_contact: bool = False, distance: float | None = None,
                       stiffness: float | None = None) -> ContactSettings:
        """Let part surfaces touch without passing through each other (IPC
        barriers, emu.contact; needs the ipctk package; FEM only so far).

        pairs         [(part, part), ...] that may touch; None: every pair of
                      different parts except bone with bone
        self_contact  also each part with itself (a fold); with ``pairs``, name (p, p)
        distance      the barrier's reach dhat in scene units (None: 5e-3 x the
                      bounding-box diagonal); surfaces in contact rest a fraction of it apart
        stiffness     the barrier's stiffness kappa, a pressure in Pa (None: the
                      softest muscle's shear modulus); contact pressure ~ kappa dhat / gap
        Scenes without it build nothing for contact. Returns the settings
        (also ``scene.contact``; ``scene.contact = None`` switches it off).
        """
        self.contact = contact_settings(list(self.parts), pairs, self_contact, distance, stiffness)
        return self.contact

    # ------------------------------------------------------------ model build
    @property
    def part_index(self) -> np.ndarray:
        """(m,) the index in ``parts`` of each tet's part, -1 for a tet of none."""
        return self._owner.copy()

    def normalised_activation(self, activation: dict) -> dict:
        """{muscle: a / its max_activation} of an absolute {muscle: a} (names
        that are not parts of the scene are left out)."""
        return {m: a / self.parts[m].max_activation for m, a in activation.items() if m in self.parts}

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
        """Give every muscle without fibres a Laplace field between its two bone
        attachments, stored in its part (emu.lowering computes the same fields for
        the model without storing them)."""
        for p in self.parts.values():
            if p.kind == "muscle" and p.fibers is None:
                p.fibers = attachment_fibers(self.points, self.tets, p.name, p.tets, self.attachments(p.name))

    def validate(self):
        """Raise ValueError (with the fix) unless the scene can be solved: parts
        cover every tet, something soft to simulate, every piece anchored, no
        welded movable bone, a finite gravity."""
        scene_checks.validate(self)

    def acap_weight_of(self, part: Part) -> float:
        """The ACAP weight of a part (tendons without an explicit weight: default_tendon_weight)."""
        if not np.isnan(part.acap_weight):
            return part.acap_weight
        return default_tendon_weight(part.mu / self.reference_shear_modulus())

    def __repr__(self):
        parts = ", ".join(f"{p.name} ({p.kind}, {len(p.tets)} tets)" for p in self.parts.values())
        return f"Scene({len(self.points)} vertices, {len(self.tets)} tets; {parts}; {len(self.pinned)} pinned)"
