"""Solved frames for ParaView: one VTU per frame (through meshio) and the
``.pvd`` collection that makes them a time series."""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..core.checks import signed_volumes
from ..core.geometry import deformation_gradients
from ..model.lowering import tet_fibers
from .mesh import write

__all__ = ["write_solution", "write_pvd", "tet_activation", "tet_fields", "read_polydata"]


def tet_activation(scene, activation) -> np.ndarray:
    """Per-tet activation (m,) from {muscle name: a} (tets of other parts: 0) or
    from an (m,) array, checked."""
    m = len(scene.tets)
    if isinstance(activation, dict):
        act = np.zeros(m)
        for name, v in activation.items():
            p = scene.parts.get(name)
            if p is None or p.kind != "muscle":
                raise ValueError(f"activation: no muscle named {name!r} (muscles: {', '.join(scene.muscles)})")
            act[p.tets] = float(v)
        return act
    act = np.asarray(activation, dtype=np.float64)
    if act.shape != (m,):
        raise ValueError(f"activation must be a {{muscle: a}} dict or one value per tet ({m},), got shape "
                         f"{act.shape}")
    return act


def tet_fields(scene, x: np.ndarray, fibers=None, who: str = "tet_fields") -> tuple:
    """Per tet at positions x (n, 3): the deformed unit fibre F u (m, 3), zero
    where u is, and the volume ratio J (m,). fibers: (m, 3) rest fibres (a
    Solver's ``fibers``), None: the scene's (emu.lowering.tet_fibers)."""
    fib = tet_fibers(scene) if fibers is None else np.asarray(fibers, dtype=np.float64)
    if fib.shape != (len(scene.tets), 3):
        raise ValueError(f"{who}: fibers must have shape ({len(scene.tets)}, 3), got {fib.shape}")
    F = deformation_gradients(scene.points, scene.tets, x)
    fu = np.einsum("tij,tj->ti", F, fib)
    n = np.linalg.norm(fu, axis=1, keepdims=True)
    fu = np.divide(fu, n, out=np.zeros_like(fu), where=n > 0)
    J = signed_volumes(x, scene.tets) / signed_volumes(scene.points, scene.tets)
    return fu, J


def write_solution(path, scene, solution, *, activation=None, fibers=None):
    """A solved frame as a mesh: deformed points; point data displacement (and
    velocity for a time step's solution); cell
    data part (index in scene.parts; a VTU names each part in its field data,
    "part:<name>" = index), fiber (deformed, unit), J and, if given, activation.

    solution    a Solution or its (n, 3) positions
    activation  what the frame was solved with: {muscle: absolute a} (other tets
                0) or an (m,) per-tet array; None: no activation cell data
    fibers      (m, 3) rest fibre directions per tet (a Solver's ``fibers``);
                None: the scene's (a Laplace field, computed and not stored, for a
                muscle that has none; see emu.lowering.tet_fibers)
    """
    x = np.asarray(getattr(solution, "positions", solution), dtype=np.float64)
    if x.shape != scene.points.shape:
        raise ValueError(f"write_solution: positions must have shape {scene.points.shape}, got {x.shape}")
    part = scene.part_index.astype(np.int32)
    fu, J = tet_fields(scene, x, fibers, "write_solution")
    cell_data = {"part": part, "fiber": fu}
    if activation is not None:
        cell_data["activation"] = tet_activation(scene, activation)
    cell_data["J"] = J
    point_data = {"displacement": x - scene.points}
    v = getattr(solution, "velocities", None)
    if v is not None:   # a time step's (emu.Dynamics)
        point_data["velocity"] = np.asarray(v, dtype=np.float64)
    write(path, x, scene.tets, cell_data=cell_data, point_data=point_data, part_names=dict(enumerate(scene.parts)))


def write_pvd(path, entries):
    """entries: [(time, relative file name)] -> a ParaView collection file."""
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1">', "  <Collection>"]
    for t, name in entries:
        lines.append(f'    <DataSet timestep="{t:.9g}" part="0" file={quoteattr(name)}/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    with open(path, "w") as f:
        f.write("\n".join(lines))


def read_polydata(path) -> tuple:
    """A triangle surface (V (n, 3) float64, F (f, 3) int64) from a VTK XML
    PolyData file (.vtp) with ASCII data arrays, as OpenSim's geometry files
    are; polygons of more than three corners are split into fans. Raises
    ValueError naming the file for binary or appended data (convert it with
    ParaView: File > Save Data, data mode Ascii) or a malformed file."""
    import xml.etree.ElementTree as ET

    path = str(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise ValueError(f"{path}: not a readable VTK XML file ({e})") from None
    piece = root.find("PolyData/Piece")
    if root.get("type") != "PolyData" or piece is None:
        raise ValueError(f"{path}: not a VTK PolyData file (VTKFile type={root.get('type')!r})")

    def array(where, name=None):
        for a in piece.findall(f"{where}/DataArray"):
            if name is None or a.get("Name") == name:
                if a.get("format", "ascii") != "ascii":
                    raise ValueError(f"{path}: {where} data is {a.get('format')!r}, only ascii is read; "
                                     "save it as ASCII (ParaView: File > Save Data, data mode Ascii)")
                try:
                    return np.array((a.text or "").split(), dtype=np.float64)
                except ValueError:
                    raise ValueError(f"{path}: {where} holds a value that is not a number") from None
        raise ValueError(f"{path}: no {where} {name or ''} data array".replace("  ", " "))

    points = array("Points")
    if points.size % 3:
        raise ValueError(f"{path}: {points.size} point coordinates, not a multiple of 3")
    V = points.reshape(-1, 3)
    conn = array("Polys", "connectivity").astype(np.int64)
    offsets = array("Polys", "offsets").astype(np.int64)
    starts = np.concatenate([[0], offsets[:-1]])
    if len(offsets) == 0 or np.any(offsets - starts < 3) or offsets[-1] != len(conn):
        raise ValueError(f"{path}: Polys offsets do not describe polygons of 3 or more corners")
    if conn.size and (conn.min() < 0 or conn.max() >= len(V)):
        raise ValueError(f"{path}: Polys connectivity refers to a point out of range [0, {len(V)})")
    F = [np.stack([np.full(e - b - 2, conn[b]), conn[b + 1:e - 1], conn[b + 2:e]], axis=1)
         for b, e in zip(starts, offsets)]
    return V, np.concatenate(F)
