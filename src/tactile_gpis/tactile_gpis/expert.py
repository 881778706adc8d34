"""A small exact GP with a zero prior mean, grown by Cholesky appends: one local expert.

Rows (X, t) as in :mod:`tactile_gpis.gp` (t = -1 value, i = d/dx_i), residual targets r
and noise variances. With K + diag(noise + jitter) = L L^T: beta = L^-1 r,
alpha = L^-T beta, mean(q) = k(X, q)^T alpha, var(q) = k(q, q) - |L^-1 k(X, q)|^2.

L is stored packed, row by row (row i holds L[i, :i+1]; n(n+1)/2 doubles, half of a
square), which is exactly BLAS's packed upper storage of L^T: solves are dtpsv, and an
append writes the new rows at the end of the buffer (no copy of the factor). Appends
return the new rows, which the caller commits only when every expert took them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.linalg.blas import dtpsv, dtrsm

from .gp import FactorError, cross_cov
from .kernels import Kernel


def packed_solve(ap: np.ndarray, n: int, B: np.ndarray, transpose: bool = False) -> np.ndarray:
    """L^-1 B (or L^-T B) for the row-packed lower-triangular L (n, n) and B (n,) or (n, k)."""
    if B.ndim == 1:
        return dtpsv(n, ap, B, lower=0, trans=0 if transpose else 1)
    if B.shape[1] > 16:  # many right-hand sides: one level-3 solve on the unpacked factor
        L = np.zeros((n, n))
        L[np.tril_indices(n)] = ap
        return dtrsm(1.0, L, np.asarray(B, float), lower=1, trans_a=int(transpose))
    out = np.empty_like(B, dtype=float)
    for j in range(B.shape[1]):
        out[:, j] = dtpsv(n, ap, np.ascontiguousarray(B[:, j]), lower=0, trans=0 if transpose else 1)
    return out


def _pack(L: np.ndarray) -> np.ndarray:
    return L[np.tril_indices(len(L))]


class Append(NamedTuple):
    """Rows computed by :meth:`ExpertGP.append`, committed by :meth:`ExpertGP.commit`."""

    X: np.ndarray
    t: np.ndarray
    resid: np.ndarray
    noise: np.ndarray
    packed_rows: np.ndarray
    beta: np.ndarray


class ExpertGP:
    """Exact GP on a few hundred rows, zero prior mean, appended block by block."""

    def __init__(self, kernel: Kernel, dim: int, jitter: float) -> None:
        self.kernel, self.dim, self.jitter = kernel, dim, float(jitter)
        self.X = np.zeros((0, dim))
        self.t = np.zeros(0, np.int64)
        self.resid = np.zeros(0)
        self.noise = np.zeros(0)
        self._ap = np.zeros(0)
        self.beta = np.zeros(0)
        self.alpha = np.zeros(0)

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def ap(self) -> np.ndarray:
        """The packed factor (n(n+1)/2,) (a view)."""
        n = self.n
        return self._ap[: n * (n + 1) // 2]

    def solve(self, B: np.ndarray, transpose: bool = False) -> np.ndarray:
        """L^-1 B (or L^-T B)."""
        return packed_solve(self.ap, self.n, B, transpose)

    def build(self, X: np.ndarray, t: np.ndarray, resid: np.ndarray, noise: np.ndarray) -> None:
        """Factor all rows at once (O(n^3))."""
        self.__init__(self.kernel, self.dim, self.jitter)
        if not len(t):
            return
        K = cross_cov(self.kernel, X, t, X, t)
        K[np.diag_indices_from(K)] += noise + self.jitter
        try:
            L = np.linalg.cholesky(K)
        except np.linalg.LinAlgError as exc:
            raise FactorError(f"expert Cholesky failed for {len(t)} rows: increase the noise or the jitter") from exc
        self.X, self.t, self.resid, self.noise = X.copy(), np.asarray(t).copy(), resid.copy(), noise.copy()
        self._ap = _pack(L)
        self.beta = self.solve(resid)
        self.alpha = self.solve(self.beta, True)

    def append(self, X: np.ndarray, t: np.ndarray, resid: np.ndarray, noise: np.ndarray,
               K12: np.ndarray, K22: np.ndarray) -> Append:
        """The B new rows (K12 = K(X_old, X) (n, B), K22 = K(X, X) without noise).

        Raises:
            FactorError: the rows make the covariance singular (nothing is changed).
        """
        n, B = self.n, len(t)
        S = K22 + np.diag(noise + self.jitter)
        if n:
            L21T = self.solve(K12)
            S = S - L21T.T @ L21T
            r2 = resid - L21T.T @ self.beta
        else:
            L21T, r2 = np.zeros((0, B)), resid
        try:
            L22 = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            L22 = None
        if L22 is None or not np.isfinite(L22).all() or np.diag(L22).min() <= 0:
            raise FactorError(f"expert Cholesky update failed for {B} new row(s) at n={n}: the observation "
                              "duplicates or contradicts earlier ones; increase the noise variances or the jitter")
        rows = np.concatenate([np.r_[L21T[:, k], L22[k, : k + 1]] for k in range(B)])
        return Append(X, t, resid, noise, rows, np.linalg.solve(L22, r2))

    def commit(self, a: Append) -> None:
        n = self.n
        used, need = n * (n + 1) // 2, len(a.packed_rows)
        if used + need > len(self._ap):
            buf = np.empty(max(used + need, len(self._ap) + max(64, len(self._ap) // 4)))
            buf[:used] = self._ap[:used]
            self._ap = buf
        self._ap[used : used + need] = a.packed_rows
        self.X = np.vstack([self.X, a.X])
        self.t = np.r_[self.t, a.t]
        self.resid = np.r_[self.resid, a.resid]
        self.noise = np.r_[self.noise, a.noise]
        self.beta = np.r_[self.beta, a.beta]
        self.alpha = self.solve(self.beta, True)

    def set_residuals(self, resid: np.ndarray) -> None:
        """New targets for the same rows (the factor is unchanged): O(n^2)."""
        if not self.n:
            return
        self.resid = resid.copy()
        self.beta = self.solve(resid)
        self.alpha = self.solve(self.beta, True)

    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (self.X, self.t, self.resid, self.noise, self._ap, self.beta, self.alpha)))
