"""Smooth closed surfaces for anatomy: bones as capsules, muscle bellies as
spindles. Each returns (V (n, 3), F (f, 3)): a closed, manifold triangle
surface with outward normals (counter-clockwise seen from outside), a
surface of revolution about the segment p0 -> p1."""
from __future__ import annotations

import numpy as np

__all__ = ["revolve", "capsule", "spindle"]


def _frame(axis: np.ndarray) -> tuple:
    a = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, helper)
    u /= np.linalg.norm(u)
    return a, u, np.cross(a, u)


def revolve(p0, p1, radius_of, rings: int = 24, segments: int = 24) -> tuple:
    """The surface of revolution about p0 -> p1 whose radius at parameter s in
    [0, 1] along it is radius_of(s) (zero at both ends: closed by two poles).

    rings  latitude rings between the poles;  segments  points per ring."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    a, u, v = _frame(p1 - p0)
    length = np.linalg.norm(p1 - p0)
    s = 0.5 - 0.5 * np.cos(np.linspace(0, np.pi, rings + 2)[1:-1])   # denser near the poles
    r = np.array([radius_of(x) for x in s])
    if np.any(r <= 0):
        raise ValueError("revolve: the radius must be positive strictly between the ends")
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v)   # (segments, 3)
    V = [p0] + [p0 + x * length * a + ri * ring[k] for x, ri in zip(s, r) for k in range(segments)] + [p1]
    V = np.asarray(V)
    F = []
    last = len(V) - 1
    for k in range(segments):
        F.append([0, 1 + (k + 1) % segments, 1 + k])
    for i in range(rings - 1):
        for k in range(segments):
            a0, b0 = 1 + i * segments + k, 1 + i * segments + (k + 1) % segments
            F += [[a0, b0, a0 + segments], [b0, b0 + segments, a0 + segments]]
    base = 1 + (rings - 1) * segments
    for k in range(segments):
        F.append([base + k, base + (k + 1) % segments, last])
    return V, np.asarray(F, np.int64)


def capsule(p0, p1, radius: float, rings: int = 24, segments: int = 24) -> tuple:
    """A bone shaft: a cylinder of ``radius`` with hemispherical ends, its
    poles at p0 and p1 (so its length is |p1 - p0|, at least 2 radius)."""
    length = np.linalg.norm(np.asarray(p1, float) - np.asarray(p0, float))
    if not length > 2 * radius > 0:
        raise ValueError(f"capsule: the length {length:g} must exceed the diameter {2 * radius:g}")
    c = radius / length

    def r(s):
        if s < c:
            return np.sqrt(max(radius ** 2 - (radius - s * length) ** 2, 0.0))
        if s > 1 - c:
            return np.sqrt(max(radius ** 2 - (radius - (1 - s) * length) ** 2, 0.0))
        return radius
    return revolve(p0, p1, r, rings, segments)


def spindle(p0, p1, radius: float, rings: int = 24, segments: int = 24, end_radius: float = 0.0) -> tuple:
    """A fusiform muscle belly between p0 and p1: radius ``radius`` at the
    middle, tapering as sin(pi s) ** 0.75 toward the ends (end_radius > 0
    keeps a tendon-like neck of that radius until a short round cap)."""
    def r(s):
        return max(radius * np.sin(np.pi * s) ** 0.75, min(end_radius, radius * np.sin(np.pi * s) ** 0.25))
    return revolve(p0, p1, r, rings, segments)
