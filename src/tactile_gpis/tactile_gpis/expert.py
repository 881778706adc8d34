"""A small exact GP with a zero prior mean, grown by Cholesky appends: one local expert.

Rows (X, t) as in :mod:`tactile_gpis.gp` (t = -1 value, i = d/dx_i), residual targets r
and noise variances. With K + diag(noise + jitter) = L L^T: beta = L^-1 r,
alpha = L^-T beta, mean(q) = k(X, q)^T alpha, var(q) = k(q, q) - |L^-1 k(X, q)|^2.

L is stored in row blocks of ``BLOCK`` rows: block b holds L[b*BLOCK : (b+1)*BLOCK, :
(b+1)*BLOCK] (zeros above the diagonal), so the factor takes about n^2/2 doubles (as
packed storage) plus BLOCK/2 per row, and an append writes its rows into the last block
(whose rows grow by doubling; no copy of the rest of the factor). A triangular solve reads every block once for all its
right-hand sides (one gemm and one small trsm per block): the B = 1 + d right-hand sides
of an append cost one pass over the factor, where the packed (dtpsv) solves before cost
one pass each (measured: the append was memory-bound on those passes). Appends return
the new rows, which the caller commits only when every expert took them.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple, Optional

import numpy as np
from scipy.linalg import solve_triangular
from scipy.linalg.blas import dtrsm

from .gp import FactorError, cross_cov
from .kernels import Kernel

#: rows per block of the factor: fewer, larger blocks cut the per-block call overhead of a
#: solve, smaller ones the zero upper part of each diagonal block (not tuned)
BLOCK = 128

_UIDS = itertools.count()  # one id per factor built (caches keyed on a factor tell a rebuild)


class BlockedFactor:
    """A lower-triangular factor L (n, n) in row blocks, grown by rows.

    Block b is L[r0:r1, :r1] (r0 = b * BLOCK) held as its off-diagonal part
    L[r0:r1, :r0] (C order, read by gemm) and its diagonal square L[r0:r1, r0:r1]
    (Fortran order, read by trsm without a copy).
    """

    def __init__(self) -> None:
        self.n = 0
        self.off: list[np.ndarray] = []
        self.diag: list[np.ndarray] = []

    @classmethod
    def from_dense(cls, L: np.ndarray) -> "BlockedFactor":
        f = cls()
        f.append_rows(L)
        return f

    def append_rows(self, R: np.ndarray) -> None:
        """Append rows R (B, >= n + B): row j holds L[n + j, : n + j + 1] (zeros beyond)."""
        R = np.atleast_2d(R)
        done = 0
        while done < len(R):
            b, r = divmod(self.n, BLOCK)
            take = min(BLOCK - r, len(R) - done)
            if b == len(self.off):
                self.off.append(np.zeros((0, BLOCK * b)))
                self.diag.append(np.zeros((0, BLOCK), order="F"))
            if len(self.off[b]) < r + take:  # the last block's rows grow by doubling (small experts)
                cap = min(BLOCK, max(2 * (r + take), 16))
                off, diag = np.zeros((cap, BLOCK * b)), np.zeros((cap, BLOCK), order="F")
                off[:r], diag[:r] = self.off[b][:r], self.diag[b][:r]
                self.off[b], self.diag[b] = off, diag
            r0 = b * BLOCK
            rows = R[done:done + take]
            self.off[b][r:r + take] = rows[:, :r0]
            w = min(BLOCK, rows.shape[1] - r0)
            self.diag[b][r:r + take, :w] = rows[:, r0:r0 + w]
            self.n += take
            done += take

    def solve(self, B: np.ndarray, transpose: bool = False) -> np.ndarray:
        """L^-1 B (or L^-T B) for B (n,) or (n, k)."""
        vec = np.ndim(B) == 1
        X = np.array(B, dtype=float, order="C").reshape(self.n, -1)
        n, nb = self.n, len(self.off)
        order = range(nb - 1, -1, -1) if transpose else range(nb)
        for b in order:
            r0, r1 = b * BLOCK, min(n, (b + 1) * BLOCK)
            m = r1 - r0
            D = self.diag[b] if m == BLOCK else np.asfortranarray(self.diag[b][:m, :m])
            if not transpose:
                if r0:
                    X[r0:r1] -= self.off[b][:m] @ X[:r0]
                X[r0:r1] = dtrsm(1.0, D, X[r0:r1], lower=1)
            else:
                X[r0:r1] = dtrsm(1.0, D, X[r0:r1], lower=1, trans_a=1)
                if r0:
                    X[:r0] -= self.off[b][:m].T @ X[r0:r1]
        return X[:, 0] if vec else X

    def rows(self, r0: int, r1: int) -> np.ndarray:
        """L[r0:r1, :r1] (r1 - r0, r1) dense (the rows appended since r0)."""
        out = np.zeros((r1 - r0, r1))
        for b in range(r0 // BLOCK, (r1 - 1) // BLOCK + 1 if r1 > r0 else r0 // BLOCK):
            b0 = b * BLOCK
            s, e = max(r0, b0), min(r1, b0 + BLOCK)
            out[s - r0: e - r0, :b0] = self.off[b][s - b0: e - b0]
            w = min(BLOCK, r1 - b0)
            out[s - r0: e - r0, b0: b0 + w] = self.diag[b][s - b0: e - b0, :w]
        return out

    def dense(self) -> np.ndarray:
        """L (n, n) (for tests)."""
        L = np.zeros((self.n, self.n))
        for b in range(len(self.off)):
            r0, r1 = b * BLOCK, min(self.n, (b + 1) * BLOCK)
            L[r0:r1, :r0] = self.off[b][: r1 - r0]
            L[r0:r1, r0:r1] = self.diag[b][: r1 - r0, : r1 - r0]
        return L

    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.off) + sum(a.nbytes for a in self.diag))


class Append(NamedTuple):
    """Rows computed by :meth:`ExpertGP.append`, committed by :meth:`ExpertGP.commit`."""

    X: np.ndarray
    t: np.ndarray
    resid: np.ndarray
    noise: np.ndarray
    rows: np.ndarray  #: (B, n + B) the new rows of L
    beta: np.ndarray


class ExpertGP:
    """Exact GP on a few hundred rows, zero prior mean, appended block by block.

    ``alpha`` = L^-T beta is computed when first read after a change (predictions at
    query points need it; the band caches of :mod:`tactile_gpis.local` use
    W = L^-1 K(X, nodes) and beta instead, so an append does not need it).
    """

    def __init__(self, kernel: Kernel, dim: int, jitter: float) -> None:
        self.kernel, self.dim, self.jitter = kernel, dim, float(jitter)
        self.X = np.zeros((0, dim))
        self.t = np.zeros(0, np.int64)
        self.resid = np.zeros(0)
        self.noise = np.zeros(0)
        self.L = BlockedFactor()
        self.beta = np.zeros(0)
        self._alpha: Optional[np.ndarray] = np.zeros(0)
        self.uid = next(_UIDS)  #: new for every factor built from scratch (appends keep it)
        self.rev = 0  #: bumped whenever beta changes (appends, new residuals)

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def alpha(self) -> np.ndarray:
        """(n,) K^-1 r (computed on first use after a change: one back substitution)."""
        if self._alpha is None:
            self._alpha = self.solve(self.beta, True)
        return self._alpha

    def solve(self, B: np.ndarray, transpose: bool = False) -> np.ndarray:
        """L^-1 B (or L^-T B)."""
        return self.L.solve(B, transpose)

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
        self.L = BlockedFactor.from_dense(L)
        self.beta = self.solve(resid)
        self._alpha = None

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
        rows = np.hstack([L21T.T, L22])  # (B, n + B), L22 lower: zeros above its diagonal
        return Append(X, t, resid, noise, rows, solve_triangular(L22, r2, lower=True, check_finite=False))

    def commit(self, a: Append) -> None:
        self.L.append_rows(a.rows)
        self.X = np.vstack([self.X, a.X])
        self.t = np.concatenate([self.t, a.t])
        self.resid = np.concatenate([self.resid, a.resid])
        self.noise = np.concatenate([self.noise, a.noise])
        self.beta = np.concatenate([self.beta, a.beta])
        self._alpha = None
        self.rev += 1

    @staticmethod
    def solve_rows(a: Append, W: np.ndarray, K2q: np.ndarray) -> np.ndarray:
        """The B new rows of W = L^-1 K(X, Q) after the append ``a``: (B, q) from the old
        W (n, q) and K2q = K(a.X, Q) (B, q). O(B n q)."""
        n = a.rows.shape[1] - len(a.t)
        rhs = K2q - a.rows[:, :n] @ W if n else K2q
        return solve_triangular(a.rows[:, n:], rhs, lower=True, check_finite=False)

    def set_residuals(self, resid: np.ndarray) -> None:
        """New targets for the same rows (the factor is unchanged): O(n^2)."""
        if not self.n:
            return
        self.resid = resid.copy()
        self.beta = self.solve(resid)
        self._alpha = None
        self.rev += 1

    def nbytes(self) -> int:
        alpha = self._alpha if self._alpha is not None else self.beta
        return int(sum(a.nbytes for a in (self.X, self.t, self.resid, self.noise, self.beta, alpha))
                   + self.L.nbytes())
