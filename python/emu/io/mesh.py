"""Mesh input and output through meshio (VTU, VTK, MSH, MESH, ...).

``read`` keeps only the tetrahedra and their cell data; a ``part`` label comes
from cell data named ``part`` (the shared scenes), ``gmsh:physical`` (gmsh
physical groups, named by their physical names where the file has them) or
``medit:ref`` (Medit references). A ``scene.json`` beside the file (the
shared scenes' format, and what `emu mesh` writes) names the parts and their
kinds: ``{"parts": [{"id": 0, "name": "humerus", "kind": "bone"}, ...]}``;
it overrides the file's names.
"""
from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..core.checks import weld_coincident
from ..core.fibers import attachment_fibers
from ..model.scene import MeshWarning, Scene

__all__ = ["TetMesh", "read", "write", "load_scene"]

_PART_KEYS = ("part", "gmsh:physical", "medit:ref")


@dataclass
class TetMesh:
    points: np.ndarray                 # (n, 3)
    tets: np.ndarray                   # (m, 4)
    cell_data: dict = field(default_factory=dict)   # name -> (m, ...) arrays
    part_names: dict = field(default_factory=dict)  # part id -> name
    part_kinds: dict = field(default_factory=dict)  # part id -> "muscle" | "tendon" | "bone"

    @property
    def part(self) -> np.ndarray | None:
        for k in _PART_KEYS:
            if k in self.cell_data:
                return np.asarray(self.cell_data[k]).astype(np.int64).ravel()
        return None

    @property
    def fiber(self) -> np.ndarray | None:
        f = self.cell_data.get("fiber")
        return None if f is None else np.asarray(f, dtype=np.float64).reshape(-1, 3)


def read(path) -> TetMesh:
    """Read a tet mesh. Raises FileNotFoundError / ValueError with the reason."""
    import meshio

    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        mesh = meshio.read(path)
    except (Exception, SystemExit) as e:  # meshio raises many types, and some readers call sys.exit
        raise ValueError(f"could not read {path} as a mesh ({type(e).__name__}: {e})") from None
    blocks = [i for i, c in enumerate(mesh.cells) if c.type == "tetra"]
    if not blocks:
        types = sorted({c.type for c in mesh.cells})
        raise ValueError(f"{path} holds no tetrahedra (cell types: {types}); tetrahedralise it first "
                         "(TetWild, gmsh -3)")
    tets = np.concatenate([mesh.cells[i].data for i in blocks]).astype(np.int64)
    cell_data = {}
    for name, per_block in mesh.cell_data.items():
        arrs = [np.asarray(per_block[i]) for i in blocks]
        cell_data[name] = np.concatenate(arrs)
    out = TetMesh(points=np.asarray(mesh.points, dtype=np.float64)[:, :3].copy(), tets=tets, cell_data=cell_data)
    if "gmsh:physical" in cell_data and "part" not in cell_data:
        # gmsh physical names: field data {name: [tag, dimension]}; the volumes' name the parts
        for name, (tag, dim) in ((k, np.asarray(v).ravel()[:2]) for k, v in (mesh.field_data or {}).items()
                                 if np.asarray(v).size >= 2):
            if int(dim) == 3:
                out.part_names[int(tag)] = str(name)
    for key, value in (mesh.field_data or {}).items():
        if key.startswith(PART_NAME_PREFIX) and np.asarray(value).size == 1:   # emu's VTU part names
            out.part_names[int(np.asarray(value).ravel()[0])] = key[len(PART_NAME_PREFIX):]
    meta = os.path.join(os.path.dirname(path), "scene.json")
    if os.path.exists(meta):
        with open(meta) as f:
            info = json.load(f)
        for p in info.get("parts", []):
            out.part_names[int(p["id"])] = p["name"]
            out.part_kinds[int(p["id"])] = p.get("kind", "muscle")
    return out


# VTU field data naming the parts: one Int32 array per part, "part:<name>",
# holding its id in the ``part`` cell data (ParaView lists them under Field Data).
PART_NAME_PREFIX = "part:"


def _vtu_part_names(path: str, part_names: dict) -> None:
    """Insert the part names as FieldData into a VTU meshio wrote (meshio's VTU
    writer drops field data)."""
    from xml.sax.saxutils import quoteattr

    arrays = "".join(f'<DataArray type="Int32" Name={quoteattr(PART_NAME_PREFIX + str(name))} '
                     f'NumberOfTuples="1" format="ascii">{int(pid)}</DataArray>\n'
                     for pid, name in sorted(part_names.items()))
    with open(path) as f:
        text = f.read()
    text = text.replace("<UnstructuredGrid>\n", f"<UnstructuredGrid>\n<FieldData>\n{arrays}</FieldData>\n", 1)
    with open(path, "w") as f:
        f.write(text)


def write(path, points, tets, *, cell_data: dict | None = None, point_data: dict | None = None,
          part_names: dict | None = None):
    """Write a tet mesh; the format follows the extension (.vtu, .vtk, .msh, .mesh, ...).
    part_names  {part id: name} of the ``part`` cell data: a VTU names them in
                its field data (PART_NAME_PREFIX + name = id), which read() reads back."""
    import meshio

    cells = [("tetra", np.asarray(tets, dtype=np.int64))]
    cd = {k: [np.asarray(v)] for k, v in (cell_data or {}).items()}
    pd = {k: np.asarray(v) for k, v in (point_data or {}).items()}
    path = os.fspath(path)
    # meshio maps .msh to ANSYS first; gmsh is what users mean (and keeps cell data)
    fmt = "gmsh" if path.lower().endswith(".msh") else None
    meshio.write_points_cells(path, np.asarray(points, dtype=np.float64), cells,
                              point_data=pd or None, cell_data=cd or None, file_format=fmt)
    if part_names and path.lower().endswith(".vtu"):
        _vtu_part_names(path, part_names)


def load_scene(path, *, muscle_youngs=6e4, bone_youngs=1e10, poisson=0.49, free_bones=(), warn=True,
               fibers="file", kinds=None, other_fibers=None, weld=False):
    """A Scene from a labelled tet mesh (the shared scenes, `emu mesh`'s output,
    or any mesh with part labels: cell data ``part``, ``gmsh:physical`` or
    ``medit:ref``).

    kinds   {part name: "muscle" | "tendon" | "bone"}: overrides the kinds of a
            ``scene.json`` beside the mesh; a part named in neither is a muscle
    fibers  the muscles' fibres: "file" (``fiber`` cell data), "laplace" (a
            Laplace field between the muscle's two bone attachments), or a dict
            {muscle name: "file" | "laplace" | (3,) direction}, the muscles it
            does not name taking other_fibers ("file" or "laplace"; None:
            "file" where the mesh has fibres, else "laplace")
    weld    merge vertices that lie at the same point (a mesh whose parts were
            meshed apart: emu.checks.weld_coincident; vertex ids change); without
            it such cracks between parts are reported with a MeshWarning
    Bones are fixed, except those named in free_bones, which the muscles move."""
    mesh = read(path)
    part = mesh.part
    if part is None:
        raise ValueError(f"{path} has no part labels (cell data 'part', 'gmsh:physical' or 'medit:ref')")
    fib = mesh.fiber
    part, fib = label_unlabelled_tets(mesh.tets, part, fib, path=path, warn=warn)
    names = {int(p): mesh.part_names.get(int(p), f"part{p}") for p in np.unique(part)}
    kind_of = _part_kinds(path, {n: mesh.part_kinds.get(pid, "muscle") for pid, n in names.items()}, kinds)
    fiber_of = _fiber_choices(path, fibers, kind_of, fib is not None, other_fibers)
    points, tets = mesh.points, mesh.tets
    if weld:
        points, tets, _ = weld_coincident(points, tets)
    with warnings.catch_warnings():
        if not warn:
            warnings.simplefilter("ignore")
        scene = Scene(points, tets, warn=warn)
    free_bones = [free_bones] if isinstance(free_bones, str) else list(free_bones)
    bone_names = [n for n, k in kind_of.items() if k == "bone"]
    unknown = sorted(set(free_bones) - set(bone_names))
    if unknown:
        raise ValueError(f"free_bones: {path} has no bone named {', '.join(map(repr, unknown))} "
                         f"(bones: {', '.join(bone_names) or 'none'})")
    for pid, name in names.items():
        idx = np.flatnonzero(part == pid)
        _add_part(scene, path, name, kind_of[name], idx, fiber_of.get(name), fib, muscle_youngs, bone_youngs,
                  poisson, fixed=name not in free_bones)
    for name, how in fiber_of.items():
        if isinstance(how, str) and how == "laplace":
            try:
                scene.parts[name].fibers = attachment_fibers(scene.points, scene.tets, name, scene.parts[name].tets,
                                                             scene.attachments(name))
            except ValueError as e:
                raise ValueError(f"{e}. {FIBER_FIX.format(name=name)}") from None
    if warn:
        _warn_unjoined(scene, path)
    return scene


def _part_kinds(path, kind_of: dict, kinds) -> dict:
    """{part name: kind}: the file's (or scene.json's) kinds with ``kinds`` over them, checked."""
    for name, kind in (kinds or {}).items():
        if name not in kind_of:
            raise ValueError(f"{path} has no part named '{name}' (parts: {', '.join(kind_of)})")
        if kind not in ("muscle", "tendon", "bone"):
            raise ValueError(f"part '{name}': kind must be muscle, tendon or bone, got {kind!r}")
        kind_of[name] = kind
    return kind_of


def _add_part(scene, path, name, kind, idx, how, fib, muscle_youngs, bone_youngs, poisson, fixed) -> None:
    """One labelled part into the scene: a muscle with its fibres as ``how`` says
    ("laplace": computed later, "file": the mesh's, or a direction), a tendon or a bone."""
    if kind == "muscle":
        if isinstance(how, str) and how == "laplace":
            scene.add_muscle(name, idx, None, youngs=muscle_youngs, poisson=poisson)
        elif isinstance(how, str):
            scene.add_muscle(name, idx, fib[idx], youngs=muscle_youngs, poisson=poisson)
        else:
            scene.add_muscle(name, idx, how, youngs=muscle_youngs, poisson=poisson)
    elif kind == "tendon":
        scene.add_tendon(name, idx, poisson=poisson)
    elif kind == "bone":
        scene.add_bone(name, idx, youngs=bone_youngs, poisson=poisson, fixed=fixed)
    else:
        raise ValueError(f"{path}: part '{name}' has unknown kind '{kind}' (muscle, tendon or bone)")


def _warn_unjoined(scene, path) -> None:
    """MeshWarnings for parts that touch without sharing vertices: cracks and loose contacts."""
    for a, b, n in scene.cracks():
        warnings.warn(f"{path}: {scene.parts[a].kind} '{a}' and {scene.parts[b].kind} '{b}' touch at {n} "
                      "vertex pair(s) they do not share: nothing joins them there (a muscle is not attached "
                      "there); load with weld=True (--weld, [mesh] weld = true) to join them",
                      MeshWarning, stacklevel=3)
    for soft, bone, _, area in scene.loose_contacts():
        warnings.warn(f"{path}: {scene.parts[soft].kind} '{soft}' lies on bone '{bone}' over an area of "
                      f"{area:.3g} without sharing vertices with it: nothing attaches it there. Mesh the "
                      "parts as one (emu mesh) if it is attached there; turn contact on if it slides there",
                      MeshWarning, stacklevel=3)


# What to do when a muscle has no fibres, for each front door.
FIBER_FIX = ("Give muscle '{name}' fibres: a direction or the file's (scene file: [parts.{name}] fibers = "
             "[x, y, z] or \"file\"; command line: --fibers {name}=x,y,z; Python: load_scene(..., "
             "fibers={{'{name}': (x, y, z)}})")


def _fiber_choices(path, fibers, kind_of: dict, has_file: bool, other) -> dict:
    """{muscle name: "file" | "laplace" | (3,) direction} from load_scene's fibers argument."""
    muscles = [n for n, k in kind_of.items() if k == "muscle"]
    if isinstance(fibers, str):
        if fibers not in ("file", "laplace"):
            raise ValueError(f"fibers must be 'file', 'laplace' or a {{muscle: choice}} dict, got {fibers!r}")
        out = {m: fibers for m in muscles}
    else:
        for name in fibers:
            if name not in muscles:
                raise ValueError(f"fibers: '{name}' is not a muscle of {path} (muscles: {', '.join(muscles) or 'none'})")
        other = other or ("file" if has_file else "laplace")
        out = {m: fibers.get(m, other) for m in muscles}
    for m, how in out.items():
        if isinstance(how, str):
            if how not in ("file", "laplace"):
                raise ValueError(f"fibers of '{m}' must be 'file', 'laplace' or a direction [x, y, z], got {how!r}")
            if how == "file" and not has_file:
                raise ValueError(f"{path}: muscle part '{m}' needs fibres and the mesh has no 'fiber' cell data: "
                                 "use the Laplace field between its two bone attachments (scene file: [parts."
                                 f"{m}] fibers = \"laplace\"; command line: --fibers {m}=laplace; Python: "
                                 f"load_scene(..., fibers={{'{m}': 'laplace'}})) or a direction")
        else:
            d = np.asarray(how, dtype=np.float64)
            if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
                raise ValueError(f"fibers of '{m}' must be 'file', 'laplace' or a nonzero direction [x, y, z], "
                                 f"got {how!r}")
            out[m] = d
    return out


def label_unlabelled_tets(tets, part, fiber=None, *, path="the mesh", warn=True):
    """Give each unlabelled tet (a negative ``part``, as 7 tets of the authors'
    realistic_biceps have) the labelled part that holds most of its vertices,
    repeating until every tet has a part; a tet that joins a part gets the
    normalised mean fibre of that part's tets sharing its vertices if its own is
    zero. Warns (MeshWarning) with the count.

    tets   (m, 4) vertex ids;  part  (m,) int labels;  fiber  (m, 3) or None
    Returns (part, fiber), copies. A tet that shares no vertex with any labelled
    tet is an error (label it in the mesh).
    """
    part = np.array(part, copy=True)
    todo = np.flatnonzero(part < 0)
    if len(todo) == 0:
        return part, fiber
    fiber = None if fiber is None else np.array(fiber, float, copy=True)
    nv = int(tets.max()) + 1
    joined = 0
    while len(todo):
        labelled = np.flatnonzero(part >= 0)
        ids = np.unique(part[labelled])
        # vertex_in[k, v]: vertex v belongs to a tet of part ids[k]
        vertex_in = np.zeros((len(ids), nv), bool)
        for k, pid in enumerate(ids):
            vertex_in[k, tets[labelled[part[labelled] == pid]].ravel()] = True
        progress = []
        for t in (todo if len(ids) else []):
            counts = vertex_in[:, tets[t]].sum(axis=1)
            if counts.max() == 0:
                continue
            progress.append((t, ids[int(np.argmax(counts))]))
        if not progress:
            raise ValueError(f"{path}: {len(todo)} tet(s) have no part label and share no vertex with a labelled "
                             "tet; label them in the mesh")
        for t, pid in progress:
            part[t] = pid
            if fiber is not None and not np.any(fiber[t]):
                share = np.flatnonzero((part == pid) & np.isin(tets, tets[t]).any(axis=1))
                u = fiber[share].sum(axis=0)
                if np.linalg.norm(u) > 0:
                    fiber[t] = u / np.linalg.norm(u)
        joined += len(progress)
        todo = np.flatnonzero(part < 0)
    if warn:
        warnings.warn(f"{path}: {joined} tet(s) had no part label; each joined the part holding most of its "
                      "vertices", MeshWarning, stacklevel=3)
    return part, fiber
