"""A small exact GP with a zero prior mean, grown by Cholesky appends: one local expert.

Rows (X, t) as in :mod:`tactile_gpis.gp` (t = -1 value, i = d/dx_i), residual targets r
and noise variances. With K + diag(noise + jitter) = L L^T: beta = L^-1 r,
alpha = L^-T beta, mean(q) = k(X, q)^T alpha, var(q) = k(q, q) - |L^-1 k(X, q)|^2.

The factor is kept exactly sized and Fortran-ordered, so every triangular solve goes to
BLAS (dtrsm) without a copy; an append copies L once (O(n^2) memory traffic, cheaper
than the solves' own conversions of a strided view). An append returns the new state,
which the caller commits only when every expert took the rows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.linalg.blas import dtrsm

from .gp import FactorError, cross_cov
from .kernels import Kernel


def lower_solve(L: np.ndarray, B: np.ndarray, transpose: bool = False) -> np.ndarray:
    """L^-1 B (or L^-T B) for a lower-triangular Fortran-ordered L and B (n,) or (n, k)."""
    vec = B.ndim == 1
    out = dtrsm(1.0, L, np.asfortranarray(B[:, None] if vec else B), lower=1, trans_a=int(transpose))
    return out[:, 0] if vec else out


class _State(NamedTuple):
    X: np.ndarray
    t: np.ndarray
    resid: np.ndarray
    noise: np.ndarray
    L: np.ndarray
    beta: np.ndarray
    alpha: np.ndarray


class ExpertGP:
    """Exact GP on a few hundred rows, zero prior mean, appended block by block."""

    def __init__(self, kernel: Kernel, dim: int, jitter: float) -> None:
        self.kernel, self.dim, self.jitter = kernel, dim, float(jitter)
        z = np.zeros(0)
        self.state = _State(np.zeros((0, dim)), np.zeros(0, np.int64), z, z, np.zeros((0, 0), order="F"), z, z)

    @property
    def n(self) -> int:
        return len(self.state.t)

    @property
    def X(self) -> np.ndarray:
        return self.state.X

    @property
    def t(self) -> np.ndarray:
        return self.state.t

    @property
    def L(self) -> np.ndarray:
        return self.state.L

    @property
    def alpha(self) -> np.ndarray:
        return self.state.alpha

    def build(self, X: np.ndarray, t: np.ndarray, resid: np.ndarray, noise: np.ndarray) -> None:
        """Factor all rows at once (O(n^3))."""
        if not len(t):
            self.__init__(self.kernel, self.dim, self.jitter)
            return
        K = cross_cov(self.kernel, X, t, X, t)
        K[np.diag_indices_from(K)] += noise + self.jitter
        try:
            L = np.asfortranarray(np.linalg.cholesky(K))
        except np.linalg.LinAlgError as exc:
            raise FactorError(f"expert Cholesky failed for {len(t)} rows: increase the noise or the jitter") from exc
        beta = lower_solve(L, resid)
        self.state = _State(X.copy(), t.copy(), resid.copy(), noise.copy(), L, beta, lower_solve(L, beta, True))

    def append(self, X: np.ndarray, t: np.ndarray, resid: np.ndarray, noise: np.ndarray,
               K12: np.ndarray, K22: np.ndarray) -> _State:
        """The state with B more rows (K12 = K(X_old, X) (n, B), K22 = K(X, X) without noise).

        Raises:
            FactorError: the rows make the covariance singular (nothing is changed).
        """
        s = self.state
        n, B = self.n, len(t)
        S = K22 + np.diag(noise + self.jitter)
        if n:
            L21T = lower_solve(s.L, K12)
            S = S - L21T.T @ L21T
            r2 = resid - L21T.T @ s.beta
        else:
            L21T, r2 = np.zeros((0, B)), resid
        try:
            L22 = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            L22 = None
        if L22 is None or not np.isfinite(L22).all() or np.diag(L22).min() <= 0:
            raise FactorError(f"expert Cholesky update failed for {B} new row(s) at n={n}: the observation "
                              "duplicates or contradicts earlier ones; increase the noise variances or the jitter")
        L = np.zeros((n + B, n + B), order="F")
        L[:n, :n] = s.L
        L[n:, :n] = L21T.T
        L[n:, n:] = L22
        beta = np.r_[s.beta, np.linalg.solve(L22, r2)]
        return _State(np.vstack([s.X, X]), np.r_[s.t, t], np.r_[s.resid, resid], np.r_[s.noise, noise],
                      L, beta, lower_solve(L, beta, True))

    def commit(self, state: _State) -> None:
        self.state = state

    def set_residuals(self, resid: np.ndarray) -> None:
        """New targets for the same rows (the factor is unchanged): O(n^2)."""
        s = self.state
        if not self.n:
            return
        beta = lower_solve(s.L, resid)
        self.state = s._replace(resid=resid.copy(), beta=beta, alpha=lower_solve(s.L, beta, True))

    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.state))
