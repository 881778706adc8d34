"""Prior mean functions of the implicit surface (world frame, metres)."""

from __future__ import annotations

import numpy as np

from .gp import MeanFn, zero_mean


def sphere_mean(centre_m: np.ndarray, radius_m: float) -> MeanFn:
    """m(x) = |x - c| - r (signed distance to a circle/sphere), grad m = (x - c)/|x - c|
    (zero at the centre)."""
    c = np.asarray(centre_m, float)
    if not (np.isfinite(c).all() and np.isfinite(radius_m) and radius_m > 0):
        raise ValueError(f"prior sphere needs a finite centre and a positive radius, got {c}, {radius_m}")

    def mean(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = X - c
        r = np.linalg.norm(u, axis=1)
        grad = np.divide(u, r[:, None], out=np.zeros_like(u), where=r[:, None] > 0)
        return r - radius_m, grad

    return mean


__all__ = ["sphere_mean", "zero_mean"]
