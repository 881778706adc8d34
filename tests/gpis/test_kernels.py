"""Kernel derivative blocks against central finite differences; covariance symmetry."""

import numpy as np
import pytest

from tactile_gpis.gp import cross_cov
from tactile_gpis.kernels import Matern52, SquaredExponential, ThinPlate, make_kernel

KERNELS = [ThinPlate(1.5), Matern52(0.3, 2.0), SquaredExponential(0.25, 0.5)]
H = 1e-5


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
@pytest.mark.parametrize("dim", [2, 3])
def test_derivatives_match_finite_differences(kernel, dim):
    rng = np.random.default_rng(dim)
    X = rng.uniform(0, 1, (6, dim))
    Y = rng.uniform(0, 1, (5, dim))
    gx = kernel.grad_x(X, Y)
    hxy = kernel.hess_xy(X, Y)
    for i in range(dim):
        e = np.zeros(dim)
        e[i] = H
        fd = (kernel.k(X + e, Y) - kernel.k(X - e, Y)) / (2 * H)
        np.testing.assert_allclose(gx[..., i], fd, rtol=1e-6, atol=1e-8)
        # d/dy_i of grad_x
        fd2 = (kernel.grad_x(X, Y + e) - kernel.grad_x(X, Y - e)) / (2 * H)
        np.testing.assert_allclose(hxy[..., :, i], fd2, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.name)
def test_cross_covariance_symmetric_and_finite_at_zero_distance(kernel):
    rng = np.random.default_rng(1)
    X = rng.uniform(0, 1, (4, 3))
    Xa = np.repeat(X, 4, axis=0)
    ta = np.tile([-1, 0, 1, 2], 4)
    K = cross_cov(kernel, Xa, ta, Xa, ta)
    assert np.isfinite(K).all()
    np.testing.assert_allclose(K, K.T, atol=1e-14)
    assert np.linalg.eigvalsh(K).min() > -1e-10
    # value/gradient at the same point are uncorrelated; gradient variance = -g(0)
    assert abs(K[0, 1]) < 1e-14
    np.testing.assert_allclose(K[1, 1], kernel.grad_variance)


def test_bad_kernel_parameters_raise_clear_errors():
    with pytest.raises(ValueError, match="unknown kernel type"):
        make_kernel("rbf", R_m=1, length_scale_m=1, signal_variance=1)
    with pytest.raises(ValueError, match="length scale must be positive"):
        Matern52(0.0)
    with pytest.raises(ValueError, match="R must be positive"):
        ThinPlate(-1.0)
