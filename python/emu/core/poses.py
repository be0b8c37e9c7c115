"""Rigid poses of bones: rotations about an axis, poses about a centre, and
parsing a pose given as (R, t) or a 4x4 matrix. A pose places rest points X at
x = R X + t."""
from __future__ import annotations

import numpy as np

__all__ = ["rotation", "pose_about", "parse_pose"]


def rotation(axis, degrees) -> np.ndarray:
    """The rotation matrix (3, 3) about ``axis`` (3,) by an angle in degrees (Rodrigues)."""
    k = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(k)
    if not n > 0:
        raise ValueError("rotation axis must be non-zero")
    k = k / n
    a = np.radians(degrees)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)


def pose_about(axis, degrees, centre) -> tuple:
    """(R, t) rotating by ``degrees`` about ``axis`` (3,) through ``centre`` (3,):
    x = R (X - c) + c."""
    R = rotation(axis, degrees)
    c = np.asarray(centre, dtype=np.float64)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"pose_about: centre must be a finite 3-vector, got {centre!r}")
    return R, c - R @ c


def parse_pose(name, pose) -> tuple:
    """(R, t) of bone ``name`` from (R, t) (a (3, 3) rotation and a (3,)
    translation) or a (4, 4) rigid transform; R must be a proper rotation."""
    if isinstance(pose, (tuple, list)) and len(pose) == 2:
        R, t = (np.asarray(p, dtype=np.float64) for p in pose)
    else:
        M = np.asarray(pose, dtype=np.float64)
        if M.shape != (4, 4):
            raise ValueError(f"pose of bone '{name}' must be (R, t) or a 4x4 matrix, got shape {M.shape}")
        R, t = M[:3, :3], M[:3, 3]
    if R.shape != (3, 3) or t.shape != (3,) or not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise ValueError(f"pose of bone '{name}': R must be a finite 3x3 and t a finite 3-vector")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0:
        raise ValueError(f"pose of bone '{name}': R is not a rotation (R^T R != I or det R < 0)")
    return R, t
