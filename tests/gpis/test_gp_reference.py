"""GP posterior against an independent dense reference; incremental == batch."""

import numpy as np
import pytest

from tactile_gpis.gp import GPIS, VALUE
from tactile_gpis.kernels import Matern52, SquaredExponential, ThinPlate

from reference import dense_posterior

R = 2.0


def make_kernel(kind):
    if kind == "thin_plate":
        return ThinPlate(R), {"R": R}
    if kind == "matern52":
        return Matern52(0.3, 1.0), {"ell": 0.3, "s2": 1.0}
    return SquaredExponential(0.3, 1.0), {"ell": 0.3, "s2": 1.0}


def random_data(rng, dim, n, with_grad):
    X = rng.uniform(0, 1, (n, dim))
    y = rng.normal(0, 0.1, n)
    rows_X, rows_t, rows_y, rows_noise, blocks = [], [], [], [], []
    for i in range(n):
        bx, bt, by, bn = [X[i]], [VALUE], [y[i]], [1e-4]
        if with_grad:
            g = rng.normal(size=dim)
            bx += [X[i]] * dim
            bt += list(range(dim))
            by += list(g / np.linalg.norm(g))
            bn += [1e-2] * dim
        blocks.append((np.array(bx), np.array(bt), np.array(by), np.array(bn)))
        rows_X += bx
        rows_t += bt
        rows_y += by
        rows_noise += bn
    return blocks, np.array(rows_X), np.array(rows_t), np.array(rows_y), np.array(rows_noise)


@pytest.mark.parametrize("kind", ["thin_plate", "matern52", "squared_exponential"])
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("with_grad", [False, True])
def test_posterior_matches_dense_reference(kind, dim, with_grad):
    rng = np.random.default_rng(100 * dim + 7 * with_grad + len(kind))
    kernel, kw = make_kernel(kind)
    blocks, X, t, y, noise = random_data(rng, dim, 12, with_grad)
    gp = GPIS(kernel, dim, jitter=0.0)
    for b in blocks:
        gp.add_rows(*b)
    Xq = rng.uniform(0, 1, (15, dim))
    mean, var = gp.predict(Xq)
    ref_mean, ref_var = dense_posterior(kind, X, t, y, noise, Xq, np.full(15, -1), **kw)
    np.testing.assert_allclose(mean, ref_mean, atol=1e-8, rtol=0)
    np.testing.assert_allclose(var, ref_var, atol=1e-8, rtol=0)
    # gradient of the mean = posterior mean of gradient rows
    grad = gp.predict_gradient(Xq)
    Xg = np.repeat(Xq, dim, axis=0)
    tg = np.tile(np.arange(dim), 15)
    ref_grad, _ = dense_posterior(kind, X, t, y, noise, Xg, tg, **kw)
    np.testing.assert_allclose(grad.ravel(), ref_grad, atol=1e-8, rtol=0)


@pytest.mark.parametrize("kind", ["thin_plate", "matern52"])
@pytest.mark.parametrize("dim", [2, 3])
def test_eval_set_matches_reference_with_prior_mean(kind, dim):
    rng = np.random.default_rng(5 + dim)
    kernel, kw = make_kernel(kind)
    c = np.full(dim, 0.5)

    def mean_fn(X):
        u = X - c
        r = np.linalg.norm(u, axis=1)
        return r - 0.2, u / r[:, None]

    def ref_mean(X, t):
        v, g = mean_fn(X)
        return np.where(t < 0, v, g[np.arange(len(t)), np.maximum(t, 0)])

    blocks, X, t, y, noise = random_data(rng, dim, 8, True)
    M = rng.uniform(0, 1, (40, dim))
    gp = GPIS(kernel, dim, mean_fn, jitter=0.0)
    gp.set_eval_points(M)
    for b in blocks:
        gp.add_rows(*b)
    ref_m, ref_v = dense_posterior(kind, X, t, y, noise, M, np.full(40, -1), mean_fn=ref_mean, **kw)
    np.testing.assert_allclose(gp.eval_mean(), ref_m, atol=1e-8, rtol=0)
    np.testing.assert_allclose(gp.eval_variance(), ref_v, atol=1e-8, rtol=0)


@pytest.mark.parametrize("kind", ["thin_plate", "squared_exponential"])
@pytest.mark.parametrize("with_grad", [False, True])
def test_incremental_equals_batch(kind, with_grad):
    rng = np.random.default_rng(3)
    kernel, _ = make_kernel(kind)
    blocks, *_ = random_data(rng, 2, 100, with_grad)
    M = rng.uniform(0, 1, (500, 2))
    gp = GPIS(kernel, 2, jitter=1e-10)
    gp.set_eval_points(M)
    for i, b in enumerate(blocks, start=1):
        gp.add_rows(*b)
        if i in (1, 10, 100):
            L, beta = gp.L.copy(), gp.beta.copy()
            mean, var = gp.eval_mean(), gp.eval_variance()
            # batch: every row so far in one block (one full Cholesky, V from scratch)
            batch = GPIS(kernel, 2, jitter=1e-10)
            batch.add_rows(*(np.concatenate(parts) for parts in zip(*blocks[:i])))
            batch.set_eval_points(M)
            np.testing.assert_allclose(L, batch.L, atol=1e-9)
            np.testing.assert_allclose(mean, batch.eval_mean(), atol=1e-8)
            np.testing.assert_allclose(var, batch.eval_variance(), atol=1e-8)
            gp.refit()  # the naive path of the benchmark gives the same state
            np.testing.assert_allclose(gp.eval_mean(), mean, atol=1e-10)
            np.testing.assert_allclose(gp.eval_variance(), var, atol=1e-10)
