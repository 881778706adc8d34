"""The local experts' factor storage and appends against dense numpy solves."""

import numpy as np
import pytest

from tactile_gpis.expert import BLOCK, BlockedFactor, ExpertGP
from tactile_gpis.gp import cross_cov, gradient_rows
from tactile_gpis.kernels import ThinPlate


@pytest.mark.parametrize("n", [1, 7, BLOCK - 1, BLOCK, BLOCK + 1, 2 * BLOCK + 37])
def test_blocked_factor_grown_by_rows_solves_like_the_dense_factor(n):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n))
    L = np.linalg.cholesky(A @ A.T + n * np.eye(n))
    f = BlockedFactor()
    i = 0
    while i < n:  # appends of 1-4 rows, straddling block boundaries
        b = min(int(rng.integers(1, 5)), n - i)
        f.append_rows(L[i:i + b, :i + b])
        i += b
    np.testing.assert_array_equal(f.dense(), L)
    spans = [(0, n), (n // 2, n), (max(0, n - 3), n)] + ([(BLOCK - 2, min(n, BLOCK + 3))] if n > BLOCK else [])
    for r0, r1 in spans:
        np.testing.assert_array_equal(f.rows(r0, r1), L[r0:r1, :r1])  # the rows appended since r0
    for B in (rng.normal(size=n), rng.normal(size=(n, 3)), rng.normal(size=(n, 40))):
        np.testing.assert_allclose(f.solve(B), np.linalg.solve(L, B), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(f.solve(B, True), np.linalg.solve(L.T, B), rtol=1e-10, atol=1e-12)
    assert f.nbytes() <= 8 * (n * n / 2 + (BLOCK + 16) * n + 2 * BLOCK * BLOCK)


def test_expert_appends_match_one_dense_solve_and_extend_W():
    rng = np.random.default_rng(0)
    k = ThinPlate(0.5)
    P = 0.5 + 0.05 * rng.normal(size=(60, 3))
    nrm = rng.normal(size=(60, 3))
    Q = 0.5 + 0.05 * rng.normal(size=(9, 3))
    gp = ExpertGP(k, 3, 1e-10)
    X, t, r, nv = np.zeros((0, 3)), np.zeros(0, int), np.zeros(0), np.zeros(0)
    W = np.zeros((0, len(Q)))
    for p, q in zip(P, nrm):
        Xg, tg = gradient_rows(p[None])
        Xn, tn = np.vstack([p, Xg]), np.r_[-1, tg]
        rn, nn = np.r_[0.0, q], np.r_[1e-6, np.full(3, 1e-2)]
        a = gp.append(Xn, tn, rn, nn, cross_cov(k, X, t, Xn, tn), cross_cov(k, Xn, tn, Xn, tn))
        W2 = gp.solve_rows(a, W, cross_cov(k, Xn, tn, Q, np.full(len(Q), -1)))
        gp.commit(a)
        W = np.vstack([W, W2])
        X, t, r, nv = np.vstack([X, Xn]), np.r_[t, tn], np.r_[r, rn], np.r_[nv, nn]
    K = cross_cov(k, X, t, X, t) + np.diag(nv + 1e-10)
    L = np.linalg.cholesky(K)
    Kq = cross_cov(k, X, t, Q, np.full(len(Q), -1))
    np.testing.assert_allclose(gp.L.dense(), L, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(W, np.linalg.solve(L, Kq), rtol=1e-7, atol=1e-9)
    mean = Kq.T @ np.linalg.solve(K, r)
    np.testing.assert_allclose(Kq.T @ gp.alpha, mean, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(W.T @ gp.beta, mean, rtol=1e-6, atol=1e-9)
