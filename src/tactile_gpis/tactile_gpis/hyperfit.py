"""GPIS hyperparameters by marginal likelihood (``kernel.fit``): coordinate ascent over a grid.

The GP holds n rows (x, type, y, noise): value rows of contacts (y = 0) and free-space
pseudo-observations, gradient rows of normals (docs/gpis.md). For hyperparameters θ,
with K_θ the covariance of the rows, Σ_θ = diag(noise + jitter) and the residual
r_θ = y − m_θ(X) of the prior mean,

    log p(y | θ) = −½ r_θᵀ (K_θ + Σ_θ)⁻¹ r_θ − ½ log|K_θ + Σ_θ| − n/2 log 2π
                 = −½ |β|² − Σ log Lᵢᵢ − n/2 log 2π,  K_θ + Σ_θ = L Lᵀ, β = L⁻¹ r_θ.

θ (named by their parameters, searched in this order):

- ``kernel.signal_variance``: the scale of k (thin plate: s in s(2r³ − 3Rr² + R³);
  stationary kernels: the signal variance);
- ``kernel.R_m`` (thin plate; only upward: R must stay at least the workspace diagonal) or
  ``kernel.length_scale_m`` (stationary kernels);
- ``noise.contact_var_m2``: the value noise of the contacts that did not bring their own
  (free-space rows and per-observation variances keep theirs; the normal noise stays);
- ``prior.radius_m`` (sphere prior, centre fixed). It changes only r_θ, not K_θ, so every
  evaluation factors K_θ + Σ_θ once and solves for the residuals of all grid radii together.

Each hyperparameter takes the values factor × its configured value (the grid: bounded and
deterministic). From the current θ, one hyperparameter at a time in the order above moves to
the value of its grid with the highest log p(y | θ) (a strictly higher one: ties keep the
current value, then the first in grid order); sweeps repeat until one moves nothing (two
when the first settles it), at most ``MAX_SWEEPS``. The result is a coordinate-wise optimum
on the grid. A candidate whose Cholesky factorisation fails is skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Optional, Sequence

import numpy as np
from scipy.linalg import solve_triangular

from .gp import cross_cov, gaussian_log_density, prior_rows
from .kernels import Kernel, make_kernel
from .prior import sphere_mean, zero_mean

SCALE = "kernel.signal_variance"
LENGTH = "kernel.length_scale_m"
R = "kernel.R_m"
NOISE = "noise.contact_var_m2"
RADIUS = "prior.radius_m"

#: upper bound on the sweeps of one fit (each move raises log p(y | θ) on a finite grid)
MAX_SWEEPS = 6


@dataclass(frozen=True)
class FitRows:
    """The GP's observation rows, in its order.

    Attributes:
        X: (n, d) points; t: (n,) types (−1 value, i ∂f/∂xᵢ); y: (n,) observed values;
        noise: (n,) noise variances; tuned: (n,) bool, rows whose noise is
        ``noise.contact_var_m2`` (replaced by θ's value).
    """

    X: np.ndarray
    t: np.ndarray
    y: np.ndarray
    noise: np.ndarray
    tuned: np.ndarray

    def noise_with(self, contact_var: float) -> np.ndarray:
        """(n,) noise variances with the tuned rows at ``contact_var``."""
        return np.where(self.tuned, contact_var, self.noise)


@dataclass(frozen=True)
class FitResult:
    theta: dict[str, float]
    log_marginal_likelihood: float
    sweeps: int
    evaluations: int  # factorisations


def kernel_of(kernel_type: str, theta: Mapping[str, float]) -> Kernel:
    """The kernel of θ (``kernel.R_m`` or ``kernel.length_scale_m`` as its type needs)."""
    return make_kernel(kernel_type, R_m=float(theta.get(R, 1.0)), length_scale_m=float(theta.get(LENGTH, 1.0)),
                       signal_variance=float(theta[SCALE]))


def mean_of(centre: Optional[np.ndarray], theta: Mapping[str, float]):
    """The prior mean of θ: the sphere of ``centre`` and θ's radius, or zero (no centre)."""
    return zero_mean if centre is None else sphere_mean(centre, float(theta[RADIUS]))


def search_grid(theta0: Mapping[str, float], factors: Sequence[float]) -> dict[str, np.ndarray]:
    """Per hyperparameter, the sorted distinct values factor × θ0 (factor 1 always included;
    ``kernel.R_m`` only factors ≥ 1)."""
    f = np.unique(np.append(np.asarray(factors, float), 1.0))
    return {name: np.unique((f[f >= 1.0] if name == R else f) * float(v)) for name, v in theta0.items()}


@dataclass
class _Evaluator:
    """log p(y | θ) for the grid's radii, one factorisation per (kernel, noise) of θ, cached."""

    rows: FitRows
    kernel_type: str
    jitter: float
    centre: Optional[np.ndarray]
    radii: Optional[np.ndarray]
    _unit_K: dict = field(default_factory=dict)  # shape value -> K of the kernel with scale 1
    _lml: dict = field(default_factory=dict)  # (scale, shape, noise) -> (radii,) log p, or None
    _resid: Optional[np.ndarray] = None  # (n, radii) residuals

    def residuals(self) -> np.ndarray:
        """(n, c) residuals y − m(X), one column per grid radius (one column without a sphere)."""
        if self._resid is None:
            radii = [None] if self.radii is None else self.radii
            self._resid = np.column_stack([
                self.rows.y - prior_rows(mean_of(self.centre, {RADIUS: r}), self.rows.X, self.rows.t)
                for r in radii])
        return self._resid

    def unit_K(self, theta: Mapping[str, float]) -> np.ndarray:
        """K of the rows for θ's shape (R or length scale) with scale 1 (k is linear in the scale)."""
        shape = theta.get(R, theta.get(LENGTH))
        if shape not in self._unit_K:
            kernel = kernel_of(self.kernel_type, {**theta, SCALE: 1.0})
            self._unit_K[shape] = cross_cov(kernel, self.rows.X, self.rows.t, self.rows.X, self.rows.t)
        return self._unit_K[shape]

    def per_radius(self, theta: Mapping[str, float]) -> Optional[np.ndarray]:
        """(c,) log p(y | θ) for every grid radius (θ's own radius ignored); None: Cholesky failed."""
        key = (theta[SCALE], theta.get(R, theta.get(LENGTH)), theta[NOISE])
        if key not in self._lml:
            A = theta[SCALE] * self.unit_K(theta)
            A[np.diag_indices_from(A)] += self.rows.noise_with(theta[NOISE]) + self.jitter
            try:
                L = np.linalg.cholesky(A)
            except np.linalg.LinAlgError:
                L = None
            if L is None or not (np.isfinite(np.diag(L)).all() and np.diag(L).min() > 0):
                self._lml[key] = None
            else:
                beta = solve_triangular(L, self.residuals(), lower=True, check_finite=False)
                self._lml[key] = gaussian_log_density(L, beta)
        return self._lml[key]

    def __call__(self, theta: Mapping[str, float]) -> Optional[float]:
        """log p(y | θ); None: its Cholesky failed."""
        lml = self.per_radius(theta)
        if lml is None:
            return None
        return float(lml[0] if self.radii is None else lml[int(np.argmin(np.abs(self.radii - theta[RADIUS])))])


def log_marginal_likelihood(rows: FitRows, kernel_type: str, theta: Mapping[str, float], jitter: float,
                            centre: Optional[np.ndarray] = None) -> Optional[float]:
    """log p(y | θ) of the rows (None: K + Σ not positive definite)."""
    radii = None if centre is None else np.array([float(theta[RADIUS])])
    return _Evaluator(rows, kernel_type, float(jitter), centre, radii)(theta)


def fit_hyperparameters(rows: FitRows, kernel_type: str, start: Mapping[str, float],
                        grid: Mapping[str, np.ndarray], jitter: float,
                        centre: Optional[np.ndarray] = None) -> FitResult:
    """Coordinate ascent of log p(y | θ) over ``grid`` from ``start`` (module docstring).

    ``start`` and ``grid`` are keyed by the hyperparameters searched, in search order;
    ``start``'s values must lie on the grid. ``centre``: the prior sphere's (with
    ``prior.radius_m`` in the grid), None for a zero prior mean. Start's own Cholesky
    failing returns start with log p = −inf.
    """
    radii = np.asarray(grid[RADIUS], float) if RADIUS in grid else None
    lml = _Evaluator(rows, kernel_type, float(jitter), centre, radii)
    theta = {k: float(v) for k, v in start.items()}
    best = lml(theta)
    if best is None:
        return FitResult(theta, -np.inf, 0, len(lml._lml))
    sweeps = 0
    while sweeps < MAX_SWEEPS:
        sweeps += 1
        moved = False
        for name, values in grid.items():
            for v in values:
                cand = {**theta, name: float(v)}
                value = lml(cand)
                if value is not None and value > best:
                    theta, best, moved = cand, value, True
        if not moved:
            break
    return FitResult(theta, best, sweeps, len(lml._lml))
