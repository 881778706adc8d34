"""A free-space point observes f(x) ≥ a (free_space.model 'inequality', one assumed-density step).
Oracle: scipy's truncated normal — after the point is added, the posterior at x must have the
mean and variance of the prediction N(μ, s²) truncated to [a, ∞); and it never pulls the mean down."""

import numpy as np
import pytest
from scipy.stats import truncnorm

from tactile_gpis.estimator import ShapeEstimator

A = 0.01  # free_space.value_m: the finger's centre is at least its radius off the surface


def _est(model="inequality", **over) -> ShapeEstimator:
    est = ShapeEstimator.from_params({"mode": "2d", "free_space.model": model, "free_space.value_m": A, **over})
    for p, n in [((0.44, 0.0), (-1.0, 0.0)), ((0.5, 0.06), (0.0, 1.0)), ((0.56, 0.0), (1.0, 0.0))]:
        assert est.add_observation(np.array([*p, 0.06]), np.array([*n, 0.0]), 1)[0]
    return est


@pytest.mark.parametrize("x", [(0.5, 0.0), (0.5, -0.04), (0.47, 0.05)])  # inside, the far side, near a contact
def test_the_posterior_at_a_free_space_point_takes_the_truncated_moments(x):
    est = _est()
    q = np.array([x])
    mu, s2 = (float(v[0]) for v in est.predict(q))
    assert mu < A  # the case: the estimate says inside or too close
    ok, why = est.add_observation(np.array([*x, 0.06]), None, 0)
    assert ok and why == ""
    m_after, v_after = (float(v[0]) for v in est.predict(q))
    s = np.sqrt(s2)
    ref = truncnorm((A - mu) / s, np.inf, loc=mu, scale=s)
    if ref.var() >= 1e-6 ** 2 * 4:  # the site is not at the contact-noise floor (it is clamped there)
        assert m_after == pytest.approx(ref.mean(), rel=1e-4)
        assert v_after == pytest.approx(ref.var(), rel=1e-4)
    assert m_after >= A - 1e-9 or m_after > mu  # lifted towards the constraint, never pulled down


def test_a_free_space_point_the_estimate_already_implies_adds_nothing():
    # a stationary kernel (σ_f = 1 cm): far from the circle the prior mean (the distance) is many σ above a
    est = ShapeEstimator.from_params({"mode": "2d", "free_space.model": "inequality", "free_space.value_m": A,
                                      "kernel.type": "squared_exponential", "kernel.length_scale_m": 0.02,
                                      "kernel.signal_variance": 1e-4, "prior.type": "given",
                                      "prior.centre_m": [0.5, 0.0, 0.06], "prior.radius_m": 0.03})
    for a in np.linspace(0, 2 * np.pi, 12, endpoint=False):
        n = np.array([np.cos(a), np.sin(a)])
        assert est.add_observation(np.array([*(np.array([0.5, 0.0]) + 0.03 * n), 0.06]), np.array([*n, 0.0]), 1)[0]
    x = np.array([[0.6, 0.1]])
    mu, s2 = (float(v[0]) for v in est.predict(x))
    assert truncnorm((A - mu) / np.sqrt(s2), np.inf, loc=mu, scale=np.sqrt(s2)).var() > 0.999 * s2  # no information
    q = np.array([[0.5, 0.0], [0.55, 0.0], [0.6, 0.1]])
    before = est.predict(q)
    ok, why = est.add_observation(np.array([0.6, 0.1, 0.06]), None, 0)
    assert ok and "implied" in why and est.n_free_space_implied == 1
    np.testing.assert_array_equal(before[0], est.predict(q)[0])


def test_the_equality_model_pulls_the_mean_to_the_value_where_the_inequality_model_keeps_it():
    """Where the estimate already says farther than a, an equality observation drags the mean down to a
    (the old model: with the thin-plate kernel this lowered the mean far over the workspace)."""
    x = np.array([[0.6, 0.08]])
    eq, ineq = _est("equality", **{"noise.free_space_var_m2": 1e-6}), _est()
    mu0 = float(eq.predict(x)[0][0])
    assert mu0 > 3 * A
    eq.add_observation(np.array([0.6, 0.08, 0.06]), None, 0)
    ineq.add_observation(np.array([0.6, 0.08, 0.06]), None, 0)
    assert float(eq.predict(x)[0][0]) == pytest.approx(A, abs=1e-3)
    assert float(ineq.predict(x)[0][0]) >= mu0 - 1e-9


def test_a_free_space_point_deep_inside_a_confident_estimate_pins_f_at_the_value():
    """α = (a − μ)/s ≫ 1 (the estimate sure the point is inside, the finger passed there): the truncated
    variance is lost to cancellation in floating point; the observation must still be the strongest
    (f = a at the contact noise), never dropped as uninformative."""
    est = _est()
    est.predict(np.array([[0.5, 0.0]]))
    a = np.array([0.5, 0.0, 0.06])
    row = est._free_space_row(a[:2], 1e-4)
    assert row is not None and row[1] >= est.contact_var
    # force the extreme: a prediction with μ = −1 m and s = 1 µm at the point
    est._model = lambda: type("P", (), {"predict": staticmethod(lambda q: (np.array([-1.0]), np.array([1e-12])))})()
    assert est._free_space_row(a[:2], 1e-4) == (A, est.contact_var)


@pytest.mark.parametrize("x", [(0.5, 0.0), (0.5, -0.04), (0.47, 0.05)])
def test_the_mode_posterior_lifts_the_point_to_the_bound_and_no_farther(x):
    """free_space.posterior 'mode': the posterior at x has the truncated prediction's mode max(μ, a)
    and its variance (scipy's truncnorm), so a miss never lifts the estimate past the bound."""
    est = _est(**{"free_space.posterior": "mode"})
    q = np.array([x])
    mu, s2 = (float(v[0]) for v in est.predict(q))
    assert mu < A
    ok, why = est.add_observation(np.array([*x, 0.06]), None, 0)
    assert ok and why == ""
    m_after, v_after = (float(v[0]) for v in est.predict(q))
    ref = truncnorm((A - mu) / np.sqrt(s2), np.inf, loc=mu, scale=np.sqrt(s2))
    if ref.var() >= 1e-6 ** 2 * 4:
        assert m_after == pytest.approx(A, rel=1e-4)
        assert v_after == pytest.approx(ref.var(), rel=1e-4)
    assert A - 1e-6 <= m_after < ref.mean()


def test_one_miss_before_any_contact_keeps_the_prior_with_the_mode_and_erases_it_with_the_mean():
    """The known issue of docs/gpis.md: on the thin-plate prior (s ≈ 0.28 m) one miss inside the prior
    circle lifts the mean at its centre above zero with 'mean'; with 'mode' the centre stays inside."""
    centre = np.array([[0.5, 0.0]])
    lifted = {}
    for posterior in ("mean", "mode"):
        est = ShapeEstimator.from_params({"mode": "2d", "free_space.posterior": posterior})
        assert float(est.predict(centre)[0][0]) < -0.05  # the auto prior: a 7.5 cm circle at the centre
        assert est.add_observation(np.array([0.555, 0.0, 0.06]), None, 0)[0]
        lifted[posterior] = float(est.predict(centre)[0][0])
    assert lifted["mean"] > 0.0 and lifted["mode"] < -0.02, lifted
