"""Interpolation at contacts, monotone variance, a clear error when the factor breaks."""

import numpy as np
import pytest

from tactile_gpis.gp import GPIS, FactorError
from tactile_gpis.kernels import Matern52, ThinPlate
from tactile_gpis.prior import sphere_mean

NOISE = 1e-6


@pytest.mark.parametrize("kernel", [ThinPlate(0.5), Matern52(0.05, 0.01)], ids=lambda k: k.name)
def test_mean_zero_and_variance_at_noise_level_at_contacts(kernel):
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 2 * np.pi, 15)
    X = np.array([0.5, 0.0]) + 0.05 * np.stack([np.cos(a), np.sin(a)], axis=1)
    gp = GPIS(kernel, 2, sphere_mean([0.5, 0.0], 0.08))
    for x in X:
        gp.add_observation(x, 0.0, NOISE)
    mean, var = gp.predict(X)
    assert np.abs(mean).max() < 1e-3 * 0.05  # << the prior's 3 cm offset
    assert (var <= NOISE * 1.0001).all() and (var > 0.2 * NOISE).all()


def test_variance_decreases_monotonically_as_contacts_are_added():
    rng = np.random.default_rng(1)
    M = rng.uniform(0, 0.3, (400, 2))
    gp = GPIS(ThinPlate(0.5), 2)
    gp.set_eval_points(M)
    prev = gp.eval_variance()
    for x in rng.uniform(0, 0.3, (40, 2)):
        gp.add_observation(x, 0.0, NOISE, gradient=[1.0, 0.0], gradient_noise_var=1e-2)
        var = gp.eval_variance()
        assert (var <= prev + 1e-15).all()
        assert var.mean() < prev.mean()
        prev = var
    assert (prev >= 0).all()


def test_factor_failure_is_a_clear_error_and_leaves_the_state_unchanged():
    gp = GPIS(ThinPlate(1.0), 2, jitter=0.0)
    M = np.random.default_rng(2).uniform(0, 1, (50, 2))
    gp.set_eval_points(M)
    gp.add_observation([0.2, 0.3], 0.0, 0.0)
    before = (gp.n, gp.L.copy(), gp.eval_mean(), gp.eval_variance())
    with pytest.raises(FactorError, match="increase the noise variances or the jitter"):
        gp.add_observation([0.2, 0.3], 0.1, 0.0)
    assert gp.n == before[0]
    np.testing.assert_array_equal(gp.L, before[1])
    np.testing.assert_array_equal(gp.eval_mean(), before[2])
    np.testing.assert_array_equal(gp.eval_variance(), before[3])
    gp.add_observation([0.6, 0.3], 0.0, 0.0)  # still usable
    assert gp.n == 2


def test_non_finite_rows_are_refused():
    gp = GPIS(ThinPlate(1.0), 3)
    with pytest.raises(ValueError, match="finite"):
        gp.add_observation([0.1, np.nan, 0.0], 0.0, 1e-6)
    assert gp.n == 0
