"""kernel.fit: hyperparameters by marginal likelihood, against independent computations.

The reference log marginal likelihood is scipy's multivariate normal log density of the rows'
values, with the covariance built row pair by row pair from the kernel derivatives written
out in ``reference.py`` (no Cholesky, no code of the package's own)."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from tactile_gpis.estimator import ShapeEstimator
from tactile_gpis.gp import GPIS, VALUE
from tactile_gpis.hyperfit import FitRows, fit_hyperparameters, kernel_of, log_marginal_likelihood, search_grid
from tactile_gpis.prior import sphere_mean
from tactile_gpis.state import load_state, save_state

from reference import cov, dense_posterior

JITTER = 1e-10


# -- independent reference -------------------------------------------------------------
def reference_K(kind: str, theta: dict, X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Covariance of the rows from reference.cov (thin plate: s times the unit-scale kernel)."""
    if kind == "thin_plate":
        kw, scale = {"R": theta["kernel.R_m"]}, theta["kernel.signal_variance"]
    else:
        kw, scale = {"ell": theta["kernel.length_scale_m"], "s2": theta["kernel.signal_variance"]}, 1.0
    n = len(t)
    return scale * np.array([[cov(kind, X[a], t[a], X[b], t[b], **kw) for b in range(n)] for a in range(n)])


def reference_mean(X: np.ndarray, t: np.ndarray, centre, radius: float) -> np.ndarray:
    """Sphere prior at the rows: |x - c| - r (value rows), (x - c)_i / |x - c| (gradient rows)."""
    out = np.empty(len(t))
    for i, (x, ti) in enumerate(zip(X, t)):
        d = x - centre
        out[i] = np.linalg.norm(d) - radius if ti < 0 else d[ti] / np.linalg.norm(d)
    return out


def reference_lml(kind, theta, X, t, y, noise, centre) -> float:
    K = reference_K(kind, theta, X, t) + np.diag(noise + JITTER)
    m = reference_mean(X, t, centre, theta["prior.radius_m"])
    return float(multivariate_normal(mean=m, cov=K).logpdf(y))


def contact_rows(points, normals, value_var, normal_var):
    """Value row (y = 0) and gradient rows (y = n) of each contact, built here."""
    dim = points.shape[1]
    X, t, y, noise = [], [], [], []
    for p, n in zip(points, normals):
        X += [p] * (1 + dim)
        t += [VALUE, *range(dim)]
        y += [0.0, *n]
        noise += [value_var] + [normal_var] * dim
    return np.array(X), np.array(t), np.array(y), np.array(noise)


def on_sphere(rng, n, centre, radius, sd=0.0):
    """n points around ``centre`` at ``radius`` (+ N(0, sd) radially) and their unit directions."""
    d = rng.normal(size=(n, len(centre)))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return centre + (radius + rng.normal(0, sd, (n, 1))) * d, d


def xyz(P, z=0.06):
    return P if P.shape[1] == 3 else np.column_stack([P, np.full(len(P), z)])


def fitted(dim, n_contacts, r_true, seed=0, sd=0.0, **params):
    """A fitting estimator after ``n_contacts`` contacts (with normals) on a circle / sphere of
    radius ``r_true`` around the prior centre."""
    est = ShapeEstimator.from_params({"mode": f"{dim}d", "kernel.fit": True, "lattice.points_per_axis_2d": 16,
                                      "lattice.points_per_axis_3d": 8, **params})
    P, N = on_sphere(np.random.default_rng(seed), n_contacts, est.prior_sphere[0], r_true, sd)
    for p, n in zip(xyz(P), xyz(N, 0.0)):
        assert est.add_observation(p, n, 1) == (True, "")
    return est, P, N


# -- the log marginal likelihood ---------------------------------------------------------
@pytest.mark.parametrize("dim, kind", [(2, "thin_plate"), (3, "thin_plate"), (2, "matern52"),
                                       (3, "squared_exponential")])
def test_log_marginal_likelihood_equals_scipys_density_of_the_rows(dim, kind):
    rng = np.random.default_rng(dim)
    centre = np.full(dim, 0.5)
    theta = {"kernel.signal_variance": 0.7, "kernel.R_m": 2.0, "kernel.length_scale_m": 0.3,
             "noise.contact_var_m2": 1e-4, "prior.radius_m": 0.2}
    theta = {k: v for k, v in theta.items() if k != ("kernel.length_scale_m" if kind == "thin_plate" else "kernel.R_m")}
    kernel = kernel_of(kind, theta)
    gp = GPIS(kernel, dim, sphere_mean(centre, theta["prior.radius_m"]), jitter=JITTER)
    X, t, y, noise = [], [], [], []
    for i in range(9):  # value rows, 6 of them with gradient rows
        x = rng.uniform(0, 1, dim)
        v = rng.normal(0, 0.05)
        if i % 3:
            g = rng.normal(size=dim)
            gp.add_observation(x, v, 1e-4, g, 1e-2)
            X, t, y, noise = X + [x] * (1 + dim), t + [VALUE, *range(dim)], y + [v, *g], noise + [1e-4] + [1e-2] * dim
        else:
            gp.add_observation(x, v, 1e-4)
            X, t, y, noise = X + [x], t + [VALUE], y + [v], noise + [1e-4]
    X, t, y, noise = map(np.array, (X, t, y, noise))
    expected = reference_lml(kind, theta, X, t, y, noise, centre)
    rows = FitRows(X, t, y, noise, np.zeros(len(t), bool))
    assert gp.log_marginal_likelihood() == pytest.approx(expected, rel=1e-8, abs=1e-8)
    assert log_marginal_likelihood(rows, kind, theta, JITTER, centre) == pytest.approx(expected, rel=1e-8, abs=1e-8)
    # another noise on the tuned rows only, against the reference with that noise
    rows = FitRows(X, t, y, noise, t < 0)
    other = {**theta, "noise.contact_var_m2": 4e-4}
    expected = reference_lml(kind, other, X, t, y, np.where(t < 0, 4e-4, noise), centre)
    assert log_marginal_likelihood(rows, kind, other, JITTER, centre) == pytest.approx(expected, rel=1e-8, abs=1e-8)


# -- the fit --------------------------------------------------------------------------
WIDE = [1e-3, 1e-2, 0.1, 0.3, 1.0, 3.0, 30.0]  # optima inside the grid (the default's are often at its edge)


@pytest.mark.parametrize("dim, kind, n_contacts, factors", [
    (2, "thin_plate", 11, [0.25, 0.5, 1.0, 2.0, 4.0]), (3, "thin_plate", 7, [0.25, 0.5, 1.0, 2.0, 4.0]),
    (2, "matern52", 7, [0.25, 0.5, 1.0, 2.0, 4.0]), (2, "thin_plate", 11, WIDE), (3, "matern52", 7, WIDE),
])
def test_the_fit_is_a_coordinatewise_optimum_and_the_gp_is_rebuilt_with_it(dim, kind, n_contacts, factors):
    # contacts 3 mm off a 4 cm circle / 3.5 cm sphere, normals with noise; one free-space row
    # and one contact with its own noise (their noise is not tuned); the last contact is a
    # fit point (3, 7, 11, ...)
    est = ShapeEstimator.from_params({"mode": f"{dim}d", "kernel.type": kind, "kernel.fit": True,
                                      "kernel.fit_factors": factors, "free_space.model": "equality",
                                      "lattice.points_per_axis_2d": 16, "lattice.points_per_axis_3d": 8})
    centre = est.prior_sphere[0]
    rng = np.random.default_rng(7)
    P, N = on_sphere(rng, n_contacts, centre, 0.035 if dim == 3 else 0.04, 0.003)
    N = N + rng.normal(0, 0.1, N.shape)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    free = centre + 0.09 * np.eye(dim)[0]
    assert est.add_observation(xyz(free[None])[0], None, 0) == (True, "")
    for i, (p, n) in enumerate(zip(xyz(P), xyz(N, 0.0))):
        assert est.add_observation(p, n, 1, 3e-6 if i == 1 else None) == (True, "")
    theta = est.hyperparameters
    cfg = est._theta_cfg
    assert theta != cfg and est.last_fit is not None and est.last_fit.sweeps < 6

    def rows_at(th):
        X, t, y, noise = contact_rows(P, N, th["noise.contact_var_m2"], est.normal_var)
        noise[(1 + dim)] = 3e-6  # contact 1's own value noise
        return (np.vstack([free, X]), np.r_[VALUE, t], np.r_[est.free_value, y],
                np.r_[est.free_var, noise])

    best = reference_lml(kind, theta, *rows_at(theta), centre)
    assert est.last_fit.log_marginal_likelihood == pytest.approx(best, rel=1e-7, abs=1e-7)
    # no other grid value of any one hyperparameter is more likely
    factors = np.array(factors)
    for name, value0 in cfg.items():
        for f in factors[factors >= 1] if name == "kernel.R_m" else factors:
            other = {**theta, name: f * value0}
            assert reference_lml(kind, other, *rows_at(other), centre) <= best + 1e-7 * abs(best), (name, f)
    # the GP was rebuilt with θ: posterior mean and variance against a dense solve with it
    X, t, y, noise = rows_at(theta)
    kw = {"R": theta["kernel.R_m"]} if kind == "thin_plate" else {"ell": theta["kernel.length_scale_m"],
                                                                   "s2": theta["kernel.signal_variance"]}
    scale = theta["kernel.signal_variance"] if kind == "thin_plate" else 1.0
    Q = rng.uniform(est.bounds_m[0], est.bounds_m[1], (12, dim))
    mean, var = dense_posterior(kind, X, t, y, (noise + JITTER) / scale, Q, np.full(len(Q), VALUE),
                                mean_fn=lambda A, tt: reference_mean(A, tt, centre, theta["prior.radius_m"]), **kw)
    m, v = est.predict(Q)
    np.testing.assert_allclose(m, mean, rtol=0, atol=1e-8)
    np.testing.assert_allclose(v, scale * var, rtol=0, atol=1e-9 * scale * var.max())
    np.testing.assert_allclose(est.lattice_mean().ravel()[::17], est.predict(est._lattice[::17])[0], atol=1e-10)


@pytest.mark.parametrize("dim, r_true, expected", [(2, 0.04, 0.0375), (3, 0.03, 0.0275)])
def test_the_fitted_prior_radius_is_the_grid_value_closest_to_the_true_one(dim, r_true, expected):
    # auto prior: radius 0.075 (2D) / 0.055 (3D); grid 0.25, 0.5, 1, 2, 4 x that
    est, _, _ = fitted(dim, 11, r_true, seed=dim, sd=0.0005)
    radii = est._fit_grid["prior.radius_m"]
    assert radii[np.argmin(np.abs(radii - r_true))] == pytest.approx(expected)
    assert est.hyperparameters["prior.radius_m"] == pytest.approx(expected)
    assert est.prior_sphere[1] == est.hyperparameters["prior.radius_m"]


def test_the_grid_is_factors_times_the_configured_values_and_r_only_grows():
    est = ShapeEstimator.from_params({"kernel.fit": True, "kernel.fit_factors": [0.5, 3.0],
                                      "lattice.points_per_axis_2d": 8})
    diag = float(np.linalg.norm(est.bounds_m[1] - est.bounds_m[0]))
    grid = est._fit_grid
    assert list(grid) == ["kernel.signal_variance", "kernel.R_m", "noise.contact_var_m2", "prior.radius_m"]
    np.testing.assert_allclose(grid["kernel.R_m"], [diag, 3 * diag])
    np.testing.assert_allclose(grid["noise.contact_var_m2"], [5e-7, 1e-6, 3e-6])
    np.testing.assert_allclose(grid["prior.radius_m"], [0.0375, 0.075, 0.225])
    assert list(search_grid({"kernel.length_scale_m": 0.05}, [2.0])) == ["kernel.length_scale_m"]


def test_a_candidate_whose_cholesky_fails_is_skipped():
    # two value rows at the same point: K is singular without noise, so the noise factor 0 fails
    X, t = np.array([[0.5, 0.0], [0.5, 0.0], [0.6, 0.0]]), np.full(3, VALUE)
    rows = FitRows(X, t, np.array([0.01, 0.012, 0.0]), np.full(3, 1e-6), np.ones(3, bool))
    theta = {"kernel.signal_variance": 1.0, "kernel.R_m": 1.0, "noise.contact_var_m2": 1e-6}
    grid = {"kernel.signal_variance": np.array([1.0]), "kernel.R_m": np.array([1.0]),
            "noise.contact_var_m2": np.array([0.0, 1e-6])}
    res = fit_hyperparameters(rows, "thin_plate", theta, grid, 0.0)
    assert res.theta == theta and np.isfinite(res.log_marginal_likelihood)


# -- off by default, exact path only, state, reset, parameters ---------------------------------
def _run(params, dim=2):
    est = ShapeEstimator.from_params({"mode": f"{dim}d", "lattice.points_per_axis_2d": 24,
                                      "lattice.points_per_axis_3d": 8, **params})
    rng = np.random.default_rng(5)
    P, N = on_sphere(rng, 9, est.prior_sphere[0], 0.04, 0.002)
    for i, (p, n) in enumerate(zip(xyz(P), xyz(N, 0.0))):
        est.add_observation(p, n, 1)
        if i % 3 == 2:
            est.add_observation(xyz((est.prior_sphere[0] + 0.1 * N[i])[None])[0], None, 0)
    return est


@pytest.mark.parametrize("dim", [2, 3])
def test_fit_false_is_bit_identical_to_the_parameter_absent(dim):
    absent = _run({}, dim)
    off = _run({"kernel.fit": False, "kernel.fit_every": 1, "kernel.fit_min_contacts": 1,
                "kernel.fit_factors": [0.1, 10.0]}, dim)
    assert absent.map_array().tobytes() == off.map_array().tobytes()
    assert off.hyperparameters == off._theta_cfg and off.last_fit is None
    on = _run({"kernel.fit": True}, dim)
    assert on.hyperparameters != on._theta_cfg and on.map_array().tobytes() != off.map_array().tobytes()


@pytest.mark.parametrize("method", ["local", "auto"])
def test_fit_needs_the_exact_path(method):
    with pytest.raises(ValueError, match="kernel.fit: true needs method 'exact'"):
        ShapeEstimator.from_params({"kernel.fit": True, "method": method})
    ShapeEstimator.from_params({"kernel.fit": False, "method": method, "lattice.points_per_axis_2d": 8})


@pytest.mark.parametrize("params, match", [
    ({"kernel.fit": "yes"}, "kernel.fit must be true or false"),
    ({"kernel.fit_every": 0}, "kernel.fit_every must be an integer >= 1"),
    ({"kernel.fit_every": 2.5}, "kernel.fit_every must be an integer >= 1"),
    ({"kernel.fit_min_contacts": -1}, "kernel.fit_min_contacts must be an integer >= 1"),
    ({"kernel.fit_factors": []}, "kernel.fit_factors must be a non-empty list"),
    ({"kernel.fit_factors": [1.0, -2.0]}, "kernel.fit_factors must be"),
    ({"kernel.fit_factors": [[1.0], [2.0]]}, "kernel.fit_factors must be"),
    ({"kernel.fit_factors": ["a"]}, "kernel.fit_factors must be"),
    ({"kernel.fit_factors": [float("nan")]}, "kernel.fit_factors must be"),
])
def test_bad_fit_parameters_are_one_line_value_errors(params, match):
    with pytest.raises(ValueError, match=match):
        ShapeEstimator.from_params(params)


def test_the_state_round_trip_with_fit_on_reproduces_the_estimate(tmp_path):
    est = _run({"kernel.fit": True, "kernel.fit_every": 2})
    est.add_observation([0.6, 0.1, 0.06], [1, 0, 0], 1, 4e-6)  # its own noise (not tuned)
    assert est.hyperparameters != est._theta_cfg
    loaded, doc = load_state(save_state(est, tmp_path / "estimate.json"))
    assert loaded.hyperparameters == est.hyperparameters == doc["model"]["hyperparameters"]
    Q = np.random.default_rng(1).uniform(est.bounds_m[0], est.bounds_m[1], (50, 2))
    for a, b in zip(loaded.predict(Q), est.predict(Q)):
        np.testing.assert_array_equal(a, b)
    assert loaded.map_array().tobytes() == est.map_array().tobytes()


def test_reset_returns_to_the_configured_hyperparameters_and_the_prior_map():
    est = _run({"kernel.fit": True})
    assert est.hyperparameters != est._theta_cfg
    est.reset()
    fresh = ShapeEstimator.from_params({"lattice.points_per_axis_2d": 24, "kernel.fit": True})
    assert est.hyperparameters == fresh.hyperparameters and est.last_fit is None
    assert est.map_array().tobytes() == fresh.map_array().tobytes()


def test_fit_rows_are_the_gps_rows_and_a_radius_change_alone_keeps_the_factor():
    est = _run({"kernel.fit": True})
    rows = est.fit_rows()
    np.testing.assert_array_equal(rows.X, est.gp.X)
    np.testing.assert_array_equal(rows.t, est.gp.t)
    np.testing.assert_array_equal(rows.noise, est.gp.noise)
    # set_mean (the prior radius alone) equals a batch rebuild with the same kernel and noise
    mean = sphere_mean(est.prior_sphere[0], 0.05)
    other = GPIS(est.kernel, 2, est.gp.mean_fn, est.gp.jitter)
    other.set_eval_points(est._lattice)
    other.rebuild(est.kernel, mean, rows.X, rows.t, rows.y, rows.noise)
    L = est.gp.L.copy()
    est.gp.set_mean(mean, rows.y)
    np.testing.assert_array_equal(est.gp.L, L)
    np.testing.assert_allclose(est.gp.eval_mean(), other.eval_mean(), rtol=0, atol=1e-10)
    np.testing.assert_allclose(est.gp.predict(est._lattice[::37])[0], other.predict(est._lattice[::37])[0], atol=1e-10)


def test_after_every_fit_the_estimate_is_the_batch_gp_of_its_rows_with_the_current_hyperparameters():
    # a fit after every contact; this sequence has a change of the prior radius alone (the
    # factor is kept, only the mean moves) as well as changes of the kernel and the noise
    est = ShapeEstimator.from_params({"mode": "3d", "kernel.fit": True, "kernel.fit_every": 1,
                                      "kernel.fit_min_contacts": 1, "lattice.points_per_axis_3d": 8})
    centre = est.prior_sphere[0]
    P, N = on_sphere(np.random.default_rng(3), 12, centre, 0.045, 0.002)
    changes = []
    for p, n in zip(P[:4], N[:4]):
        before = dict(est.hyperparameters)
        assert est.add_observation(p, n, 1) == (True, "")
        changes.append({k for k, v in est.hyperparameters.items() if v != before[k]})
        rows, theta = est.fit_rows(), est.hyperparameters
        ref = GPIS(kernel_of("thin_plate", theta), 3, sphere_mean(centre, theta["prior.radius_m"]), JITTER)
        ref.set_eval_points(est._lattice)
        ref.rebuild(ref.kernel, ref.mean_fn, rows.X, rows.t, rows.y, rows.noise)
        np.testing.assert_allclose(est.lattice_mean().ravel(), ref.eval_mean(), rtol=0, atol=1e-9)
        np.testing.assert_allclose(est.lattice_variance().ravel(), ref.eval_variance(), rtol=0,
                                   atol=1e-9 * est.kernel.k0)
        assert np.all(rows.noise[rows.t < 0] == theta["noise.contact_var_m2"])
    assert {"prior.radius_m"} in changes and any(len(c) > 1 for c in changes)
