"""Procedural meshes: a fusiform (spindle) muscle with tendon caps, and a
two-bone arm with a hinged elbow, a flexor and an extensor (``arm``).

The mesh is a structured grid: a square cross-section grid mapped onto a
rounded square (a blend between the square and its circumscribed circle that
keeps the corner cells from flattening: minimum tet quality stays above 0.1 at
every resolution, where a full disk mapping makes slivers), swept along the
muscle axis (z) with a spindle radius profile; every hex is split into six tets around its main diagonal
(Kuhn subdivision, conforming across hexes). About ``24 r^3`` tets for
resolution ``r`` (r=4: 1.5k tets, r=10: 24k, r=15: 81k, r=29: 585k).
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np

__all__ = ["FusiformMesh", "fusiform", "resolution_for_tets", "ArmMesh", "arm", "block_mesh", "NeckMesh", "neck"]

ROUNDING = 0.6  # 0: square cross-section, 1: disk (slivers at the corners)


@dataclass
class FusiformMesh:
    points: np.ndarray        # (n, 3) float64 rest positions
    tets: np.ndarray          # (m, 4) int64, positively oriented
    fibers: np.ndarray        # (m, 3) unit fibre directions (along the spindle's meridians)
    is_tendon: np.ndarray     # (m,) bool: tet lies in a tendon cap
    proximal: np.ndarray      # vertex ids of the z = 0 end face
    distal: np.ndarray        # vertex ids of the z = length end face
    length: float


def resolution_for_tets(tets: int) -> int:
    """The resolution whose mesh has about ``tets`` tets (24 r^3)."""
    if tets <= 0:
        raise ValueError(f"tets must be positive, got {tets}")
    return max(2, int(round((tets / 24.0) ** (1.0 / 3.0))))


def _profile(z, length, radius, end_radius):
    """Spindle radius r(z) and its derivative."""
    s = np.sin(np.pi * z / length)
    r = end_radius + (radius - end_radius) * s
    dr = (radius - end_radius) * np.cos(np.pi * z / length) * np.pi / length
    return r, dr


def fusiform(resolution: int = 6, *, tets: int | None = None, length: float = 10.0, radius: float = 1.5,
             end_radius: float = 0.5, tendon_fraction: float = 0.12) -> FusiformMesh:
    """A spindle-shaped muscle along +z with tendon caps at both ends.

    resolution       cross-section cells per side (the axis gets 4x as many)
    tets             if given, choose the resolution giving about this many tets
    length, radius   muscle length and belly radius; end_radius at the ends
    tendon_fraction  fraction of the length at each end that is tendon
    """
    if tets is not None:
        resolution = resolution_for_tets(tets)
    r = int(resolution)
    if r < 1:
        raise ValueError(f"resolution must be >= 1, got {resolution}")
    if not (0 <= tendon_fraction < 0.5):
        raise ValueError("tendon_fraction must lie in [0, 0.5)")
    if not (0 < end_radius <= radius):
        raise ValueError("need 0 < end_radius <= radius")
    nx, nz = r, 4 * r
    u = np.linspace(-1.0, 1.0, nx + 1)
    w = np.linspace(0.0, length, nz + 1)
    U, Vv, Z = np.meshgrid(u, u, w, indexing="ij")
    # square [-1,1]^2 -> rounded square: scale each point toward the circle by
    # a weight that grows from 0 at the centre to ROUNDING on the boundary
    rs, re = np.maximum(np.abs(U), np.abs(Vv)), np.hypot(U, Vv)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(re > 0, 1.0 - ROUNDING * rs ** 2 * (1.0 - rs / re), 1.0)
    dx, dy = U * f, Vv * f
    rad, _ = _profile(Z, length, radius, end_radius)
    points = np.stack([dx * rad, dy * rad, Z], axis=-1).reshape(-1, 3)

    def vid(i, j, k):
        return (i * (nx + 1) + j) * (nz + 1) + k

    I, J, K = np.meshgrid(np.arange(nx), np.arange(nx), np.arange(nz), indexing="ij")
    I, J, K = I.ravel(), J.ravel(), K.ravel()
    tets = _kuhn_tets(lambda di, dj, dk: vid(I + di, J + dj, K + dk)).astype(np.int64)
    # orient positively
    p = points[tets]
    vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0
    neg = vol < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    # fibres: tangent of the meridian through the centroid, d/dz (s r(z) e_rho, z)
    c = points[tets].mean(axis=1)
    rc, drc = _profile(c[:, 2], length, radius, end_radius)
    rho = np.hypot(c[:, 0], c[:, 1])
    s = rho / rc
    with np.errstate(invalid="ignore", divide="ignore"):
        er = np.where(rho[:, None] > 0, c[:, :2] / rho[:, None], 0.0)
    fib = np.column_stack([s * drc * er[:, 0], s * drc * er[:, 1], np.ones(len(c))])
    fib /= np.linalg.norm(fib, axis=1, keepdims=True)
    cap = tendon_fraction * length
    is_tendon = (c[:, 2] < cap) | (c[:, 2] > length - cap)
    zs = points[:, 2]
    return FusiformMesh(points=points, tets=tets, fibers=fib, is_tendon=is_tendon,
                        proximal=np.flatnonzero(np.isclose(zs, 0.0)),
                        distal=np.flatnonzero(np.isclose(zs, length)), length=length)


def _kuhn_tets(corner) -> np.ndarray:
    """The six tets of a hex around its main diagonal (Kuhn subdivision: conforming
    across neighbouring hexes), as corner paths; corner(di, dj, dk) -> vertex ids.
    Orientation is fixed by the caller."""
    tets = []
    for perm in permutations(range(3)):
        path = [(0, 0, 0)]
        cur = [0, 0, 0]
        for axis in perm:
            cur[axis] = 1
            path.append(tuple(cur))
        tets.append(np.stack([corner(*c) for c in path], axis=1))
    return np.concatenate(tets, axis=0)


def block_mesh(blocks: dict, resolution: int, size: float = 1.0, depth: int = 1):
    """A conforming tet mesh of unit blocks on an integer grid.

    blocks      {label: list of (i, j) or (i, j, k) block coordinates}; block (i, j)
                spans [i, i+1] x [j, j+1] x [0, depth], block (i, j, k)
                [i, i+1] x [j, j+1] x [k, k+1] (times size)
    resolution  hex cells per block side; each hex is six Kuhn tets, conforming
                across blocks, so neighbouring blocks share their face vertices
    Returns (points (n, 3), tets (m, 4) positively oriented, labels (m,) index
    into list(blocks)); vertices no tet uses are dropped.
    """
    r = int(resolution)
    if r < 1:
        raise ValueError(f"resolution must be >= 1, got {resolution}")
    def box(ijk):  # (i, j, k0, k1) in blocks
        return (ijk[0], ijk[1], ijk[2], ijk[2] + 1) if len(ijk) == 3 else (ijk[0], ijk[1], 0, depth)

    boxes = np.array([box(ijk) for v in blocks.values() for ijk in v])
    lo = np.array([boxes[:, 0].min(), boxes[:, 1].min(), boxes[:, 2].min()])
    ni, nj = (boxes[:, 0].max() - lo[0] + 1) * r, (boxes[:, 1].max() - lo[1] + 1) * r
    nk = (boxes[:, 3].max() - lo[2]) * r

    def vid(i, j, k):
        return (i * (nj + 1) + j) * (nk + 1) + k

    tets, labels = [], []
    for label, (name, cells) in enumerate(blocks.items()):
        for cell in cells:
            bi, bj, k0, k1 = box(cell)
            I, J, K = np.meshgrid(np.arange(r) + (bi - lo[0]) * r, np.arange(r) + (bj - lo[1]) * r,
                                  np.arange((k0 - lo[2]) * r, (k1 - lo[2]) * r), indexing="ij")
            I, J, K = I.ravel(), J.ravel(), K.ravel()
            t = _kuhn_tets(lambda di, dj, dk: vid(I + di, J + dj, K + dk))
            tets.append(t)
            labels.append(np.full(len(t), label))
    tets = np.concatenate(tets).astype(np.int64)
    labels = np.concatenate(labels)
    I, J, K = np.meshgrid(np.arange(ni + 1), np.arange(nj + 1), np.arange(nk + 1), indexing="ij")
    points = np.stack([(I.ravel() / r + lo[0]), (J.ravel() / r + lo[1]), K.ravel() / r + lo[2]], axis=1) * size
    used, inverse = np.unique(tets, return_inverse=True)
    tets = inverse.reshape(tets.shape)
    points = points[used]
    p = points[tets]
    vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
    neg = vol < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return points, tets, labels


@dataclass
class ArmMesh:
    points: np.ndarray   # (n, 3) rest positions
    tets: np.ndarray     # (m, 4)
    parts: dict          # {"humerus" | "forearm" | "flexor" | "extensor": tet ids}
    elbow: np.ndarray    # a point on the hinge axis
    axis: np.ndarray     # the hinge axis (+z: flexion is a positive turn about it)


def arm(resolution: int = 2, *, block: float = 0.02, length: int = 6) -> ArmMesh:
    """A procedural arm in the x-y plane, one block (``block`` metres) thick:

    - humerus: a rod of ``length`` blocks pointing up (+y) from the elbow;
    - forearm: a rod of ``length`` blocks pointing along +x, bent 90 degrees;
      the two bones share only the edge of vertices on the elbow axis (z
      through the origin): a hinge;
    - flexor: a diagonal band in the angle between the bones, from the front of
      the humerus to the top of the forearm (contracting it bends the elbow);
    - extensor: a band wrapped behind the elbow, from the back of the humerus to
      the underside of the forearm (contracting it straightens the elbow).

    38 blocks of 6 resolution^3 tets (resolution 2: 1.8k tets, 3: 6.2k, 4: 14.6k).
    """
    n = int(length)
    if n < 4:
        raise ValueError(f"length must be >= 4 blocks, got {length}")
    blocks = {
        "humerus": [(-1, j) for j in range(n)],
        "forearm": [(i, -1) for i in range(n)],
        "flexor": [(i, j) for i in range(n) for j in range(n) if 3 <= i + j <= 5],
        "extensor": [(-2, j) for j in range(-2, n - 1)] + [(i, -2) for i in range(-1, n // 2)],
    }
    points, tets, labels = block_mesh(blocks, resolution, size=block)
    names = list(blocks)
    parts = {name: np.flatnonzero(labels == i) for i, name in enumerate(names)}
    return ArmMesh(points=points, tets=tets, parts=parts, elbow=np.zeros(3), axis=np.array([0.0, 0.0, 1.0]))


@dataclass
class NeckMesh:
    points: np.ndarray   # (n, 3) rest positions
    tets: np.ndarray     # (m, 4)
    parts: dict          # {"torso" | "head" | four muscles: tet ids}
    joint: np.ndarray    # the ball joint's position


NECK_MUSCLES = ("left_back", "right_back", "left_front", "right_front")


def neck(resolution: int = 1, *, block: float = 0.02) -> NeckMesh:
    """A head on a ball joint moved by four neck muscles (x right, y front, z up):

    - torso: a base plate of 6 x 6 blocks and a spine column of one block up to
      z = 3 blocks;
    - head: a 6 x 6 x 2 block slab from z = 4, on a one-block stem whose lowest
      corner is the spine's top corner: the two bones share that one vertex, a
      ball joint at (1, 1, 3) blocks, right under the slab's centre;
    - four muscles: columns from the plate to the head's underside at its
      corners (left_back, right_back, left_front, right_front).

    123 blocks of 6 resolution^3 tets (resolution 1: 738 tets, 2: 5.9k).
    """
    span = range(-2, 4)
    torso = [(i, j, 0) for i in span for j in span] + [(0, 0, 1), (0, 0, 2)]
    head = [(1, 1, 3)] + [(i, j, k) for i in span for j in span for k in (4, 5)]
    cols = {"left_back": (-2, -2), "right_back": (3, -2), "left_front": (-2, 3), "right_front": (3, 3)}
    blocks = {"torso": torso, "head": head}
    for name in NECK_MUSCLES:
        i, j = cols[name]
        blocks[name] = [(i, j, k) for k in (1, 2, 3)]
    points, tets, labels = block_mesh(blocks, resolution, size=block)
    parts = {name: np.flatnonzero(labels == i) for i, name in enumerate(blocks)}
    return NeckMesh(points=points, tets=tets, parts=parts, joint=np.array([1.0, 1.0, 3.0]) * block)
