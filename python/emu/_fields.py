"""Small per-tet field helpers in numpy (for output, not for solving)."""
from __future__ import annotations

import numpy as np


def deformation_gradients(rest: np.ndarray, tets: np.ndarray, x: np.ndarray) -> np.ndarray:
    """F_t = D_s D_m^-1 for every tet: rest, x (n, 3); tets (m, 4) -> (m, 3, 3)."""
    def edges(p):
        q = p[tets]
        return np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]], axis=2)
    return edges(x) @ np.linalg.inv(edges(rest))
