"""The labelled parts of a scene (muscles, tendons, bones) and their materials."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
