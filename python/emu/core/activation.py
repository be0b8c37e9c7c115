"""Activation over time: per-muscle curves evaluated at each frame's time."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Curve"]

INTERPOLATIONS = ("linear", "smooth", "step")


@dataclass
class Curve:
    """A muscle's activation over time.

    keys           (k, 2) rows of (time, value), times increasing; or None with ``per_frame``
    per_frame      one value per frame (instead of keys)
    interpolation  "linear", "smooth" (smoothstep between keys: C1, never overshoots) or "step"
    normalized     values in [0, 1] times the muscle's max_activation; False: absolute a
    signed         any finite values (bone angles, offsets): no range checks
    Before the first key the first value holds, after the last key the last.
    """
    keys: np.ndarray | None = None
    per_frame: np.ndarray | None = None
    interpolation: str = "linear"
    normalized: bool = True
    signed: bool = False

    def __post_init__(self):
        if (self.keys is None) == (self.per_frame is None):
            raise ValueError("an activation curve needs either keys or per_frame values (not both)")
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {self.interpolation!r}")
        vals = None
        if self.keys is not None:
            k = np.asarray(self.keys, dtype=np.float64)
            if k.ndim != 2 or k.shape[1] != 2 or len(k) == 0:
                raise ValueError(f"keys must be a list of [time, value] pairs, got shape {k.shape}")
            if np.any(np.diff(k[:, 0]) <= 0):
                raise ValueError("key times must be strictly increasing")
            self.keys, vals = k, k[:, 1]
        else:
            self.per_frame = np.asarray(self.per_frame, dtype=np.float64).ravel()
            vals = self.per_frame
        if not np.all(np.isfinite(vals)):
            raise ValueError("curve values must be finite")
        if self.signed:
            return
        if np.any(vals < 0):
            raise ValueError("activation values must be finite and >= 0")
        if self.normalized and np.any(vals > 1):
            raise ValueError("normalised activation values must lie in [0, 1] (set normalized = false for "
                             "absolute values)")

    def value(self, frame: int, time: float) -> float:
        if self.per_frame is not None:
            if frame >= len(self.per_frame):
                raise ValueError(f"the per-frame activation has {len(self.per_frame)} values; frame {frame} "
                                 "has none")
            return float(self.per_frame[frame])
        t, v = self.keys[:, 0], self.keys[:, 1]
        if time <= t[0]:
            return float(v[0])
        if time >= t[-1]:
            return float(v[-1])
        i = int(np.searchsorted(t, time, side="right")) - 1
        u = (time - t[i]) / (t[i + 1] - t[i])
        if self.interpolation == "step":
            u = 0.0
        elif self.interpolation == "smooth":
            u = u * u * (3.0 - 2.0 * u)
        return float(v[i] + (v[i + 1] - v[i]) * u)
