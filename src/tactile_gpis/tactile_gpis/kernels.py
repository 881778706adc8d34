"""Radial covariance kernels k(x, y) = k(r), r = |x - y|, with the derivative blocks
needed for gradient observations.

Every kernel exposes the same interface:

- ``k(X, Y)`` -> (N, M) covariance of values;
- ``radial(r)`` -> (k(r), g(r), h(r)) with g = k'(r)/r and h = g'(r)/r, from which
  every derivative block follows (u = x - y):

  dk/dx_i = g u_i,  dk/dy_j = -g u_j,  d2k/dx_i dy_j = -(h u_i u_j + g delta_ij).

``k0`` is k(0) (the prior variance of f, the same at every point).
"""

from __future__ import annotations

import numpy as np


class Kernel:
    """Base class of radial kernels; subclasses implement :meth:`radial`."""

    name = "kernel"

    def radial(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k(r), k'(r)/r, (d/dr(k'(r)/r))/r), each finite at r = 0."""
        raise NotImplementedError

    @property
    def k0(self) -> float:
        """k(0): prior variance of the field value."""
        return float(self.radial(np.zeros(1))[0][0])

    @property
    def grad_variance(self) -> float:
        """Prior variance of each gradient component: -g(0)."""
        return float(-self.radial(np.zeros(1))[1][0])

    def k(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """(N, M) covariance k(X_i, Y_j)."""
        return self.radial(_pairwise_distance(X, Y))[0]

    def grad_x(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """(N, M, d) derivative dk(x, y)/dx at x = X_i, y = Y_j."""
        u = X[:, None, :] - Y[None, :, :]
        _, g, _ = self.radial(np.linalg.norm(u, axis=-1))
        return g[..., None] * u

    def hess_xy(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """(N, M, d, d) mixed derivative d2k(x, y)/dx_i dy_j."""
        u = X[:, None, :] - Y[None, :, :]
        _, g, h = self.radial(np.linalg.norm(u, axis=-1))
        d = X.shape[1]
        return -(h[..., None, None] * u[..., :, None] * u[..., None, :] + g[..., None, None] * np.eye(d))


def _pairwise_distance(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    d2 = (X * X).sum(1)[:, None] + (Y * Y).sum(1)[None, :] - 2.0 * X @ Y.T
    return np.sqrt(np.maximum(d2, 0.0))


class ThinPlate(Kernel):
    """Williams & Fitzgibbon thin-plate kernel k(r) = s (2r^3 - 3R r^2 + R^3), 0 <= r <= R.

    R must exceed every distance between points that ever meet in the kernel
    (fix it from the workspace diagonal at construction so incremental updates stay
    valid). g = 6 s (r - R), h = 6 s / r (h u u^T = 6 s r u_hat u_hat^T -> 0 at r = 0).
    """

    name = "thin_plate"

    def __init__(self, R_m: float, scale: float = 1.0) -> None:
        if not (np.isfinite(R_m) and R_m > 0):
            raise ValueError(f"thin-plate R must be positive, got {R_m}")
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"kernel scale must be positive, got {scale}")
        self.R_m = float(R_m)
        self.scale = float(scale)

    def radial(self, r):
        r = np.asarray(r, dtype=float)
        R, s = self.R_m, self.scale
        k = s * (2.0 * r**3 - 3.0 * R * r**2 + R**3)
        g = s * 6.0 * (r - R)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = np.where(r > 0, s * 6.0 / np.where(r > 0, r, 1.0), 0.0)
        return k, g, h


class _Stationary(Kernel):
    """A stationary kernel with a length scale l (m) and a signal variance s2."""

    def __init__(self, length_scale_m: float, signal_variance: float = 1.0) -> None:
        _check_stationary(length_scale_m, signal_variance)
        self.length_scale_m = float(length_scale_m)
        self.signal_variance = float(signal_variance)


class Matern52(_Stationary):
    """Matern 5/2: k = s2 (1 + a + a^2/3) exp(-a), a = sqrt(5) r / l.

    g = -s2 (5 / (3 l^2)) (1 + a) exp(-a), h = s2 (25 / (3 l^4)) exp(-a).
    """

    name = "matern52"

    def radial(self, r):
        r = np.asarray(r, dtype=float)
        l, s2 = self.length_scale_m, self.signal_variance
        a = np.sqrt(5.0) * r / l
        e = np.exp(-a)
        k = s2 * (1.0 + a + a * a / 3.0) * e
        g = -s2 * (5.0 / (3.0 * l * l)) * (1.0 + a) * e
        h = s2 * (25.0 / (3.0 * l**4)) * e
        return k, g, h


class SquaredExponential(_Stationary):
    """Squared exponential: k = s2 exp(-r^2 / (2 l^2)); g = -k / l^2, h = k / l^4."""

    name = "squared_exponential"

    def radial(self, r):
        r = np.asarray(r, dtype=float)
        l, s2 = self.length_scale_m, self.signal_variance
        k = s2 * np.exp(-0.5 * (r / l) ** 2)
        return k, -k / l**2, k / l**4


def _check_stationary(length_scale_m: float, signal_variance: float) -> None:
    if not (np.isfinite(length_scale_m) and length_scale_m > 0):
        raise ValueError(f"kernel length scale must be positive, got {length_scale_m}")
    if not (np.isfinite(signal_variance) and signal_variance > 0):
        raise ValueError(f"kernel signal variance must be positive, got {signal_variance}")


KERNEL_TYPES = ("thin_plate", "matern52", "squared_exponential")


def make_kernel(kind: str, *, R_m: float, length_scale_m: float, signal_variance: float) -> Kernel:
    """Kernel by name: 'thin_plate' (uses R_m, signal_variance as scale), 'matern52',
    'squared_exponential'."""
    if kind == "thin_plate":
        return ThinPlate(R_m, signal_variance)
    if kind == "matern52":
        return Matern52(length_scale_m, signal_variance)
    if kind == "squared_exponential":
        return SquaredExponential(length_scale_m, signal_variance)
    raise ValueError(f"unknown kernel type '{kind}'; expected one of {KERNEL_TYPES}")
