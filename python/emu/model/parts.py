"""The labelled parts of a scene (muscles, tendons, bones) and their materials."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.checks import integer_ids
from ..core.fibers import laplace_fibers

__all__ = ["Part", "lame", "default_tendon_weight", "BONE_ACAP_WEIGHT"]

# ACAP weight of movable bones' tets: the fitted bone positions follow the
# bone's rotation to about 1/weight of the soft tissue's pull (docs/DESIGN.md,
# "Bones and joints"); large weights only touch the small dense bone block.
BONE_ACAP_WEIGHT = 1e4


def lame(youngs: float, poisson: float) -> tuple[float, float]:
    """(mu, lambda) from Young's modulus and Poisson ratio."""
    if not youngs > 0:
        raise ValueError(f"Young's modulus must be positive, got {youngs}")
    if not 0 < poisson < 0.5:
        raise ValueError(f"Poisson ratio must lie in (0, 0.5), got {poisson}")
    mu = youngs / (2.0 * (1.0 + poisson))
    lam = youngs * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    return mu, lam


def default_tendon_weight(stiffness_ratio: float) -> float:
    """ACAP weight for a part `stiffness_ratio` times stiffer than the muscles."""
    return float(min(max(stiffness_ratio, 1.0), 1e3) ** 0.5)


@dataclass
class Part:
    name: str
    kind: str               # "muscle", "tendon" or "bone"
    tets: np.ndarray        # tet ids
    youngs: float
    poisson: float
    density: float
    acap_weight: float
    fibers: np.ndarray | None = None   # (len(tets), 3) unit vectors, muscles only
    max_activation: float = 1e5        # a for normalised activation 1.0
    fixed: bool = True                 # bones: fixed (or scripted) rather than moved by the muscles
    joint_stiffness: float = 0.0       # movable bones: passive rotational stiffness (N m / rad)

    def __repr__(self) -> str:
        """One line: the part's name, kind, size and material, not its tet ids."""
        extra = "" if self.kind != "bone" else (", fixed" if self.fixed else ", movable")
        return (f"Part({self.name!r}, {self.kind}, {len(self.tets)} tets, youngs={self.youngs:g}, "
                f"poisson={self.poisson:g}{extra})")

    @property
    def mu(self) -> float:
        return lame(self.youngs, self.poisson)[0]


def part_tet_ids(name: str, tets, owner: np.ndarray, part_names: list) -> np.ndarray:
    """A new part's tet ids, checked: tets as ids or a boolean mask over the
    scene's tets, none twice, none of another part (owner: (m,) index in
    part_names per tet, -1 for none), and a name not taken."""
    m = len(owner)
    idx = np.asarray(tets)
    if idx.dtype == bool:
        if idx.shape != (m,):
            raise ValueError(f"part '{name}': a boolean tet mask must have shape ({m},), got {idx.shape}")
        idx = np.flatnonzero(idx)
    idx = integer_ids(idx, f"part '{name}': tet ids").ravel()
    if idx.size == 0:
        raise ValueError(f"part '{name}' has no tets")
    if idx.min() < 0 or idx.max() >= m:
        raise ValueError(f"part '{name}': tet ids must lie in [0, {m}), got [{idx.min()}, {idx.max()}]")
    if len(np.unique(idx)) != len(idx):
        raise ValueError(f"part '{name}' lists some tets twice")
    taken = owner[idx] >= 0
    if taken.any():
        other = part_names[owner[idx[taken][0]]]
        raise ValueError(f"part '{name}': {taken.sum()} tet(s) already belong to part '{other}'")
    if name in part_names:
        raise ValueError(f"a part named '{name}' exists already")
    return idx


def muscle_fibers(points, tets, name: str, fibers=None, origin=None, insertion=None):
    """A muscle's (k, 3) unit fibre directions (tets: its (k, 4) tets): the given
    ones ((k, 3) or one (3,) for all), a Laplace field from the origin to the
    insertion vertex ids, or None (resolved between its bone attachments when
    the scene is solved)."""
    if fibers is None:
        if (origin is None) != (insertion is None):
            raise ValueError(f"muscle '{name}': give both origin and insertion vertex ids, or neither")
        if origin is None:
            return None
        try:
            return laplace_fibers(points, tets, origin, insertion)
        except ValueError as e:
            raise ValueError(f"muscle '{name}': {e}") from None
    f = np.asarray(fibers, dtype=np.float64)
    if f.shape == (3,):
        f = np.tile(f, (len(tets), 1))
    if f.shape != (len(tets), 3):
        raise ValueError(f"muscle '{name}': fibers must have shape ({len(tets)}, 3) or (3,), got {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError(f"muscle '{name}': fibers contain NaN or inf")
    norm = np.linalg.norm(f, axis=1)
    if np.any(norm < 1e-12):
        raise ValueError(f"muscle '{name}': {np.sum(norm < 1e-12)} fibre direction(s) are zero")
    return f / norm[:, None]
