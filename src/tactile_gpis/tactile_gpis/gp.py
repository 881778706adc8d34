"""Gaussian process with value and gradient observations, incremental Cholesky updates
and a maintained evaluation set (the map).

Observation rows: each row is a point x and a type t: t = -1 observes f(x), t = i >= 0
observes df/dx_i. With the prior mean m(x) and the joint covariance K (+ noise on the
diagonal) = L L^T, the posterior at a query row q is (Rasmussen & Williams, Alg. 2.1)

    mu(q) = m(q) + w^T beta,  var(q) = k(q, q) - |w|^2,  w = L^-1 k(X, q),
    beta = L^-1 (y - m(X)).

Adding a block of B rows appends to L in O(n^2 B) (never refactoring), and for a fixed
evaluation set M keeps V = L^-1 K(X, M), appending B rows in O(n B |M|), so the mean and
variance over M update in O(n |M|) per observation.
"""

from __future__ import annotations

from typing import Callable, Optional

import numpy as np
from scipy.linalg import solve_triangular

from .kernels import Kernel

#: mean function: (N, d) points -> ((N,) value, (N, d) gradient)
MeanFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

VALUE = -1  # row type of a value observation
_CHUNK_ELEMS = 2_000_000  # elements of the (Na, chunk, d) difference array per chunk
_V_BLOCK_ROWS = 64  # V is stored in blocks of rows, so growing it never copies it


class FactorError(np.linalg.LinAlgError):
    """The Cholesky factor cannot take the new rows (not positive definite)."""


def zero_mean(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """m(x) = 0."""
    return np.zeros(len(X)), np.zeros_like(X)


def cross_cov(kernel: Kernel, Xa: np.ndarray, ta: np.ndarray, Xb: np.ndarray, tb: np.ndarray) -> np.ndarray:
    """(Na, Nb) covariance between observation rows (Xa, ta) and (Xb, tb).

    With u = xa - xb, v = 1 for value rows, e the unit vector of a gradient row,
    ua = u.e_a, ub = u.e_b:
    cov = va vb k + g (ua vb - va ub) - (1 - va)(1 - vb)(h ua ub + g e_a.e_b).
    Computed in column chunks to bound memory.
    """
    Xa = np.asarray(Xa, float)
    Xb = np.asarray(Xb, float)
    ta = np.asarray(ta)
    tb = np.asarray(tb)
    na, d = Xa.shape
    nb = Xb.shape[0]
    out = np.empty((na, nb))
    va = (ta < 0).astype(float)
    Ea = np.zeros((na, d))
    Ea[np.nonzero(ta >= 0)[0], ta[ta >= 0]] = 1.0
    all_values_a = bool(va.all())
    step = max(1, _CHUNK_ELEMS // max(1, na * d))
    for s in range(0, nb, step):
        e = min(nb, s + step)
        Xc, tc = Xb[s:e], tb[s:e]
        u = Xa[:, None, :] - Xc[None, :, :]
        k, g, h = kernel.radial(np.sqrt(np.einsum("ijd,ijd->ij", u, u)))
        vb = (tc < 0).astype(float)
        if all_values_a and vb.all():
            out[:, s:e] = k
            continue
        Eb = np.zeros((e - s, d))
        Eb[np.nonzero(tc >= 0)[0], tc[tc >= 0]] = 1.0
        ua = np.einsum("ijd,id->ij", u, Ea)
        ub = np.einsum("ijd,jd->ij", u, Eb)
        cov = va[:, None] * vb[None, :] * k + g * (ua * vb[None, :] - va[:, None] * ub)
        cov -= np.outer(1.0 - va, 1.0 - vb) * (h * ua * ub + g * (Ea @ Eb.T))
        out[:, s:e] = cov
    return out


def prior_rows(mean_fn: MeanFn, X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n,) prior mean of each observation row: m(x) for a value row, dm/dx_t for a gradient row."""
    m_val, m_grad = mean_fn(X)
    return np.where(t < 0, m_val, m_grad[np.arange(len(t)), np.maximum(t, 0)])


def gaussian_log_density(L: np.ndarray, beta: np.ndarray):
    """log N(r; 0, L L^T) = -|beta|^2/2 - sum log diag L - n/2 log 2 pi, given beta = L^-1 r.

    ``beta`` (n,) gives a float; (n, c) gives (c,), one log density per residual column
    (several prior means against one factor)."""
    n = len(L)
    quad = beta @ beta if beta.ndim == 1 else np.einsum("ic,ic->c", beta, beta)
    return -0.5 * quad - np.log(np.diag(L)).sum() - 0.5 * n * np.log(2 * np.pi)


def gradient_rows(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows observing every gradient component at each point: (N*d, d) points, (N*d,) types."""
    n, d = X.shape
    return np.repeat(X, d, axis=0), np.tile(np.arange(d), n)


def _forward_substitute(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """L^-1 B for a small lower-triangular L (b, b) and a wide B (b, M), row by row."""
    out = np.empty_like(B)
    for i in range(len(L)):
        out[i] = (B[i] - L[i, :i] @ out[:i]) / L[i, i] if i else B[i] / L[i, i]
    return out


class GPIS:
    """GP over f: R^d -> R with value/gradient rows, appended block by block.

    Args:
        kernel: covariance of f.
        dim: 2 or 3.
        mean_fn: prior mean m(x) with its gradient (default zero).
        jitter: added to the diagonal of every new block (besides the noise).
    """

    def __init__(self, kernel: Kernel, dim: int, mean_fn: Optional[MeanFn] = None, jitter: float = 1e-10) -> None:
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim}")
        self.kernel = kernel
        self.dim = dim
        self.mean_fn = mean_fn or zero_mean
        self.jitter = float(jitter)
        self._eval: Optional[np.ndarray] = None
        self.reset()

    # -- state ---------------------------------------------------------------
    def reset(self) -> None:
        """Drop every observation (keeps the evaluation set)."""
        self.n = 0
        self._cap = 0
        self.X = np.zeros((0, self.dim))
        self.t = np.zeros(0, dtype=int)
        self.resid = np.zeros(0)  # y - m(X)
        self.noise = np.zeros(0)
        self._L = np.zeros((0, 0))
        self._beta = np.zeros(0)
        self._V = None
        if self._eval is not None:
            self.set_eval_points(self._eval)

    @property
    def L(self) -> np.ndarray:
        """(n, n) lower Cholesky factor of K(X, X) + diag(noise + jitter)."""
        return self._L[: self.n, : self.n]

    @property
    def beta(self) -> np.ndarray:
        """L^-1 (y - m(X))."""
        return self._beta[: self.n]

    def _grow(self, need: int) -> None:
        if need <= self._cap:
            return
        cap = max(need, self._cap + max(16, self._cap // 4))  # 1.25x: at most ~1.6x the memory needed
        L = np.zeros((cap, cap))
        L[: self.n, : self.n] = self.L
        beta = np.zeros(cap)
        beta[: self.n] = self.beta
        self._L, self._beta = L, beta
        self._cap = cap

    # -- observations --------------------------------------------------------
    def add_rows(self, X: np.ndarray, t: np.ndarray, y: np.ndarray, noise_var: np.ndarray,
                 K12: Optional[np.ndarray] = None, K22: Optional[np.ndarray] = None) -> None:
        """Append a block of B rows (points, types, observed values, noise variances).

        O(n^2 B) for the factor and O(n B |M|) for the evaluation set. ``K12`` (n, B) and
        ``K22`` (B, B, without noise) may be passed when the caller already has them.

        Raises:
            FactorError: the block makes the covariance numerically singular; the
                state is left unchanged.
        """
        X = np.atleast_2d(np.asarray(X, float))
        t = np.atleast_1d(np.asarray(t, int))
        y = np.atleast_1d(np.asarray(y, float))
        noise_var = np.broadcast_to(np.asarray(noise_var, float), t.shape)
        B = len(t)
        if X.shape != (B, self.dim) or y.shape != (B,):
            raise ValueError(f"rows must be X (B, {self.dim}), t (B,), y (B,); got {X.shape}, {t.shape}, {y.shape}")
        if not (np.isfinite(X).all() and np.isfinite(y).all() and np.isfinite(noise_var).all()):
            raise ValueError("observation rows must be finite")
        if (noise_var < 0).any():
            raise ValueError("noise variances must be >= 0")
        resid = y - prior_rows(self.mean_fn, X, t)
        n = self.n
        if K12 is None:
            K12 = cross_cov(self.kernel, self.X, self.t, X, t)
        if K22 is None:
            K22 = cross_cov(self.kernel, X, t, X, t)
        K22 = K22 + np.diag(noise_var + self.jitter)
        L21T = solve_triangular(self.L, K12, lower=True, check_finite=False) if n else np.zeros((0, B))
        S = K22 - L21T.T @ L21T
        try:
            L22 = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            L22 = None
        if L22 is None or not np.isfinite(L22).all() or np.diag(L22).min() <= 0:
            raise FactorError(
                f"Cholesky update failed for {B} new row(s) at n={n} (Schur complement min eigenvalue "
                f"{np.linalg.eigvalsh(0.5 * (S + S.T)).min():.3g}): the observation duplicates or "
                "contradicts earlier ones; increase the noise variances or the jitter"
            )
        beta_new = solve_triangular(L22, resid - L21T.T @ self.beta, lower=True, check_finite=False)
        self._grow(n + B)
        self._L[n : n + B, :n] = L21T.T
        self._L[n : n + B, n : n + B] = L22
        self._beta[n : n + B] = beta_new
        if self._eval is not None:
            Kb = cross_cov(self.kernel, X, t, self._eval, np.full(len(self._eval), VALUE))
            self._v_subtract_product(Kb, L21T)
            Vnew = _forward_substitute(L22, Kb)
            self._v_store(n, Vnew)
            self._eval_mean += np.einsum("bm,b->m", Vnew, beta_new)
            self._eval_vsum += np.einsum("ij,ij->j", Vnew, Vnew)
        self.X = np.vstack([self.X, X])
        self.t = np.concatenate([self.t, t])
        self.resid = np.concatenate([self.resid, resid])
        self.noise = np.concatenate([self.noise, noise_var])
        self.n = n + B

    def add_observation(
        self,
        x: np.ndarray,
        value: float,
        value_noise_var: float,
        gradient: Optional[np.ndarray] = None,
        gradient_noise_var: float = 0.0,
    ) -> None:
        """One point: its value f(x) = value and optionally its gradient (one block of 1 or 1+d rows)."""
        x = np.asarray(x, float).reshape(1, self.dim)
        if gradient is None:
            self.add_rows(x, [VALUE], [value], [value_noise_var])
            return
        Xg, tg = gradient_rows(x)
        self.add_rows(
            np.vstack([x, Xg]),
            np.concatenate([[VALUE], tg]),
            np.concatenate([[value], np.asarray(gradient, float).reshape(self.dim)]),
            np.concatenate([[value_noise_var], np.full(self.dim, gradient_noise_var)]),
        )

    @property
    def alpha(self) -> np.ndarray:
        """(K + N)^-1 (y - m(X)) = L^-T beta: mu(q) = m(q) + k(X, q)^T alpha."""
        if self.n == 0:
            return np.zeros(0)
        return solve_triangular(self.L, self.beta, lower=True, trans="T", check_finite=False)

    def refit(self) -> None:
        """Batch refit from all rows: full Cholesky (O(n^3)) and, if an evaluation set is
        kept, V from scratch (O(n^2 |M|)). The naive path; equals the incremental state."""
        K = cross_cov(self.kernel, self.X, self.t, self.X, self.t) + np.diag(self.noise + self.jitter)
        try:
            L = np.linalg.cholesky(K)
        except np.linalg.LinAlgError as exc:
            raise FactorError(f"batch Cholesky failed at n={self.n}: increase noise or jitter") from exc
        self._L = L
        self._beta = solve_triangular(L, self.resid, lower=True, check_finite=False) if self.n else np.zeros(0)
        self._cap = self.n
        if self._eval is not None:
            self.set_eval_points(self._eval)

    def rebuild(self, kernel: Kernel, mean_fn: MeanFn, X: np.ndarray, t: np.ndarray, y: np.ndarray,
                noise_var: np.ndarray) -> None:
        """Replace the kernel, the prior mean and every row (e.g. new hyperparameters), in one
        batch factorisation: O(n^3), and O(n^2 |M|) for the evaluation set.

        Raises:
            FactorError: K + diag(noise + jitter) is not positive definite; the state is
                left unchanged.
        """
        X = np.asarray(X, float).reshape(-1, self.dim)
        t = np.asarray(t, int).reshape(-1)
        y = np.asarray(y, float).reshape(-1)
        noise_var = np.asarray(noise_var, float).reshape(-1)
        if not len(X) == len(t) == len(y) == len(noise_var):
            raise ValueError(f"rows differ in length: {len(X)} points, {len(t)} types, {len(y)} values, "
                             f"{len(noise_var)} noise variances")
        old = self.kernel, self.mean_fn, self.n, self.X, self.t, self.resid, self.noise
        self.kernel, self.mean_fn = kernel, mean_fn
        if not len(t):
            self.reset()
            return
        self.n, self.X, self.t, self.noise = len(t), X, t, noise_var
        self.resid = y - prior_rows(mean_fn, X, t)
        try:
            self.refit()  # fails before it changes the factor or the evaluation set
        except FactorError:
            self.kernel, self.mean_fn, self.n, self.X, self.t, self.resid, self.noise = old
            raise

    def set_mean(self, mean_fn: MeanFn, y: np.ndarray) -> None:
        """Replace the prior mean only (K and the factor stay): with the rows' observed values
        ``y`` (n,), beta = L^-1 (y - m(X)) and the evaluation mean m(M) + V^T beta again,
        O(n^2 + n |M|)."""
        y = np.asarray(y, float).reshape(-1)
        if y.shape != (self.n,):
            raise ValueError(f"y must hold the {self.n} rows' values, got {y.shape}")
        self.mean_fn = mean_fn
        self.resid = y - prior_rows(mean_fn, self.X, self.t)
        if self.n:
            self._beta[: self.n] = solve_triangular(self.L, self.resid, lower=True, check_finite=False)
        if self._eval is not None:
            self._eval_prior = mean_fn(self._eval)[0]
            mean = self._eval_prior.copy()[None, :]
            self._v_subtract_product(mean, -self.beta[:, None])  # m(M) + V^T beta
            self._eval_mean = mean[0]

    # -- evaluation set ------------------------------------------------------
    def set_eval_points(self, M: np.ndarray) -> None:
        """Keep mean/variance over the fixed points M (|M|, d) up to date from now on."""
        M = np.ascontiguousarray(M, dtype=float)
        if M.ndim != 2 or M.shape[1] != self.dim:
            raise ValueError(f"evaluation points must be (M, {self.dim}), got {M.shape}")
        self._eval = M
        self._eval_prior = self.mean_fn(M)[0]
        self._V = []
        if self.n:
            Kxm = cross_cov(self.kernel, self.X, self.t, M, np.full(len(M), VALUE))
            V = solve_triangular(self.L, Kxm, lower=True, check_finite=False)
            self._v_store(0, V)
            self._eval_mean = self._eval_prior + V.T @ self.beta
            self._eval_vsum = np.einsum("ij,ij->j", V, V)
        else:
            self._eval_mean = self._eval_prior.copy()
            self._eval_vsum = np.zeros(len(M))

    def clear_eval_points(self) -> None:
        """Stop maintaining an evaluation set (frees V)."""
        self._eval = None
        self._V = None

    def _v_store(self, row: int, rows: np.ndarray) -> None:
        """Write rows of V starting at ``row``, adding blocks as needed."""
        for i in range(len(rows)):
            b, r = divmod(row + i, _V_BLOCK_ROWS)
            if b == len(self._V):
                self._V.append(np.empty((_V_BLOCK_ROWS, len(self._eval))))
            self._V[b][r] = rows[i]

    def _v_subtract_product(self, out: np.ndarray, A: np.ndarray) -> None:
        """out -= A^T V[:n] for A (n, B), block by block."""
        for b, block in enumerate(self._V):
            s = b * _V_BLOCK_ROWS
            e = min(self.n, s + _V_BLOCK_ROWS)
            if e <= s:
                break
            # einsum, not BLAS: this memory-bound product runs single-threaded and
            # does not suffer from BLAS thread contention on a loaded machine
            out -= np.einsum("ib,im->bm", A[s:e], block[: e - s])

    @property
    def eval_points(self) -> Optional[np.ndarray]:
        return self._eval

    def eval_mean(self) -> np.ndarray:
        """(M,) posterior mean over the evaluation set."""
        return self._eval_mean.copy()

    def eval_variance(self) -> np.ndarray:
        """(M,) posterior variance over the evaluation set, clipped at 0."""
        return np.maximum(self.kernel.k0 - self._eval_vsum, 0.0)

    # -- prediction ----------------------------------------------------------
    def predict(self, Xq: np.ndarray, return_var: bool = True):
        """Posterior mean (and variance, clipped at 0) of f at (N, d) points."""
        Xq = np.atleast_2d(np.asarray(Xq, float))
        mean = self.mean_fn(Xq)[0]
        if self.n == 0:
            return (mean, np.full(len(Xq), self.kernel.k0)) if return_var else mean
        W = solve_triangular(self.L, cross_cov(self.kernel, self.X, self.t, Xq, np.full(len(Xq), VALUE)),
                             lower=True, check_finite=False)
        mean = mean + W.T @ self.beta
        if not return_var:
            return mean
        return mean, np.maximum(self.kernel.k0 - np.einsum("ij,ij->j", W, W), 0.0)

    def predict_gradient(self, Xq: np.ndarray) -> np.ndarray:
        """(N, d) posterior mean of grad f at (N, d) points."""
        Xq = np.atleast_2d(np.asarray(Xq, float))
        grad = self.mean_fn(Xq)[1].copy()
        if self.n == 0:
            return grad
        Xg, tg = gradient_rows(Xq)
        W = solve_triangular(self.L, cross_cov(self.kernel, self.X, self.t, Xg, tg), lower=True, check_finite=False)
        return grad + (W.T @ self.beta).reshape(len(Xq), self.dim)

    def log_marginal_likelihood(self) -> float:
        """log p(y) = -|beta|^2/2 - sum log diag L - n/2 log 2 pi
        (= log N(y; m(X), K + diag(noise + jitter)))."""
        return float(gaussian_log_density(self.L, self.beta))
