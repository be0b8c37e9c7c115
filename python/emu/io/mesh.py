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

from ..scene import MeshWarning, Scene

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
    meta = os.path.join(os.path.dirname(path), "scene.json")
    if os.path.exists(meta):
        with open(meta) as f:
            info = json.load(f)
        for p in info.get("parts", []):
            out.part_names[int(p["id"])] = p["name"]
            out.part_kinds[int(p["id"])] = p.get("kind", "muscle")
    return out


def write(path, points, tets, *, cell_data: dict | None = None, point_data: dict | None = None):
    """Write a tet mesh; the format follows the extension (.vtu, .vtk, .msh, .mesh, ...)."""
    import meshio

    cells = [("tetra", np.asarray(tets, dtype=np.int64))]
    cd = {k: [np.asarray(v)] for k, v in (cell_data or {}).items()}
    pd = {k: np.asarray(v) for k, v in (point_data or {}).items()}
    path = os.fspath(path)
    # meshio maps .msh to ANSYS first; gmsh is what users mean (and keeps cell data)
    fmt = "gmsh" if path.lower().endswith(".msh") else None
    meshio.write_points_cells(path, np.asarray(points, dtype=np.float64), cells,
                              point_data=pd or None, cell_data=cd or None, file_format=fmt)


def load_scene(path, *, muscle_youngs=6e4, bone_youngs=1e10, poisson=0.49, free_bones=(), warn=True,
               fibers="file"):
    """A Scene from a labelled tet mesh (the shared scenes, or any mesh with a
    ``part`` label and ``fiber`` cell data): parts of kind ``muscle`` become
    muscles with the file's fibres (fibers="file") or a Laplace field between
    their two bone attachments (fibers="laplace"), ``tendon`` tendons, ``bone``
    bones: fixed, except those named in free_bones, which the muscles move."""
    if fibers not in ("file", "laplace"):
        raise ValueError(f"fibers must be 'file' or 'laplace', got {fibers!r}")
    mesh = read(path)
    part = mesh.part
    if part is None:
        raise ValueError(f"{path} has no part labels (cell data 'part', 'gmsh:physical' or 'medit:ref')")
    fib = mesh.fiber
    part, fib = label_unlabelled_tets(mesh.tets, part, fib, path=path, warn=warn)
    with warnings.catch_warnings():
        if not warn:
            warnings.simplefilter("ignore")
        scene = Scene(mesh.points, mesh.tets, warn=warn)
    free_bones = [free_bones] if isinstance(free_bones, str) else list(free_bones)
    bone_names = [mesh.part_names.get(int(p), f"part{p}") for p in np.unique(part)
                  if mesh.part_kinds.get(int(p), "muscle") == "bone"]
    unknown = sorted(set(free_bones) - set(bone_names))
    if unknown:
        raise ValueError(f"free_bones: {path} has no bone named {', '.join(map(repr, unknown))} "
                         f"(bones: {', '.join(bone_names) or 'none'})")
    for pid in np.unique(part):
        name = mesh.part_names.get(int(pid), f"part{pid}")
        kind = mesh.part_kinds.get(int(pid), "muscle")
        idx = np.flatnonzero(part == pid)
        if kind == "muscle":
            if fibers == "laplace":
                scene.add_muscle(name, idx, None, youngs=muscle_youngs, poisson=poisson)
                continue
            if fib is None:
                raise ValueError(f"{path}: muscle part '{name}' needs 'fiber' cell data (or load with "
                                 "fibers='laplace')")
            scene.add_muscle(name, idx, fib[idx], youngs=muscle_youngs, poisson=poisson)
        elif kind == "tendon":
            scene.add_tendon(name, idx, poisson=poisson)
        elif kind == "bone":
            scene.add_bone(name, idx, youngs=bone_youngs, poisson=poisson, fixed=name not in free_bones)
        else:
            raise ValueError(f"{path}: part '{name}' has unknown kind '{kind}' (muscle, tendon or bone)")
    if fibers == "laplace":
        scene.resolve_fibers()
    return scene


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
