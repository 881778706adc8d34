"""ShapeEstimator: parameters, rejections, map layout, table prior, export."""

import numpy as np
import pytest

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE
from tactile_gpis.estimator import PARAMETERS, ShapeEstimator, load_params

from shapes import CENTRE_3D, fibonacci_sphere

YAML = __import__("pathlib").Path(__file__).parents[2] / "src/tactile_gpis/config/gpis_estimator.yaml"


def small_2d(**kw):
    return ShapeEstimator.from_params({"lattice.points_per_axis_2d": 32, **kw})


def test_yaml_holds_every_parameter_with_the_defaults():
    p = load_params(YAML)
    assert set(p) == set(PARAMETERS)
    assert all(p[k] == PARAMETERS[k][0] for k in p)


@pytest.mark.parametrize("params, match", [
    ({"mode": "4d"}, "mode must be"),
    ({"kernel.type": "rbf"}, "unknown kernel type"),
    ({"workspace.max_m": [0.0, 0.0, 0.0]}, "must exceed"),
    ({"noise.contact_var_m2": -1.0}, ">= 0"),
    ({"prior.type": "cube"}, "prior.type"),
    ({"kernel.R_m": 0.1}, "at least the workspace diagonal"),
    ({"no_such": 1}, "unknown GPIS parameter"),
])
def test_bad_parameters_raise_value_errors(params, match):
    with pytest.raises(ValueError, match=match):
        ShapeEstimator.from_params(params)


def test_invalid_observations_are_rejected_with_reasons_and_counted():
    est = small_2d()
    assert est.add_observation([0.5, 0.05, 0.06], [0, 1, 0], 1) == (True, "")
    cases = [
        ([np.nan, 0.0, 0.06], "non-finite"),
        ([0.9, 0.0, 0.06], "outside the workspace"),
        ([0.5, 0.0503, 0.06], "duplicate"),
        ([0.45, 0.0, 0.06, 1.0], "3 coordinates"),
    ]
    for p, why in cases:
        ok, reason = est.add_observation(p, None, 1)
        assert not ok and why in reason
    ok, reason = est.add_observation([0.45, 0.0, 0.06], None, 7)
    assert not ok and "label" in reason
    assert est.n_observations == 1 and est.n_rejected == 5
    # 2D ignores z; a NaN normal is simply not used
    assert est.add_observation([0.45, 0.0, 123.0], [np.nan, 0, 0], 1)[0]
    assert est.add_observation([0.4, 0.1, 0.0], None, 0)[0]  # free space
    assert est.n_observations == 3


def test_map_layout_2d():
    est = small_2d(**{"candidates.max_count": 20})
    m = est.map_array()
    assert m.dtype == VARIANCE_MAP_DTYPE
    lat = m[m["kind"] == KIND_LATTICE]
    assert len(lat) == 32 * 32 and (m["kind"][: 32 * 32] == KIND_LATTICE).all()
    xs, ys = est.lattice_axes
    np.testing.assert_array_equal(lat["x"], np.repeat(xs, 32))  # C order: x slowest
    np.testing.assert_array_equal(lat["y"], np.tile(ys, 32))
    assert (m["z"] == 0.06).all()
    cand = m[m["kind"] == KIND_CANDIDATE]
    assert 0 < len(cand) <= 20
    # prior: circle at the workspace centre; candidates on it with outward unit normals
    r = np.hypot(cand["x"] - 0.5, cand["y"])
    np.testing.assert_allclose(r, 0.075, atol=1e-3)
    nrm = np.stack([cand["normal_x"], cand["normal_y"]], 1)
    np.testing.assert_allclose((nrm * np.stack([cand["x"] - 0.5, cand["y"]], 1)).sum(1) / r, 1, atol=1e-3)
    sp = est.surface_points()
    assert sp.shape[1] == 3 and (sp[:, 2] == 0.06).all()


def test_3d_table_prior_candidates_and_inside(tmp_path):
    est = ShapeEstimator.from_params({"mode": "3d", "lattice.points_per_axis_3d": 20, "candidates.max_count": 50,
                                      "prior.type": "given", "prior.centre_m": [0.5, 0.0, 0.0],
                                      "prior.radius_m": 0.06})
    for n in fibonacci_sphere(10):
        if n[2] > 0:
            est.add_observation(np.array([0.5, 0, 0]) + 0.06 * n, n, 1)
    m = est.map_array()
    cand = m[m["kind"] == KIND_CANDIDATE]
    assert len(cand) == 50 and (cand["z"] > 0.005).all()
    assert len(m) == 20**3 + 50
    assert not est.inside(np.array([[0.5, 0.0, -0.01]]))[0]
    assert est.inside(np.array([[0.5, 0.0, 0.01]]))[0]
    path = est.export_shape(tmp_path / "shape.stl")
    assert path.stat().st_size > 84


def test_reset_returns_to_the_prior_and_export_csv(tmp_path):
    est = small_2d()
    prior = est.map_array()
    est.add_observation([0.5, 0.05, 0.06], [0, 1, 0], 1)
    assert not np.array_equal(est.map_array()["variance"], prior["variance"])
    est.export_shape(tmp_path / "c.csv")
    rows = (tmp_path / "c.csv").read_text().splitlines()
    assert rows[0] == "x_m,y_m,loop" and len(rows) > 10
    est.reset()
    assert est.n_observations == 0
    np.testing.assert_array_equal(est.map_array(), prior)


def test_candidate_variance_and_mean_match_direct_prediction():
    est = small_2d()
    for a in np.linspace(0, 2 * np.pi, 6, endpoint=False):
        n = np.array([np.cos(a), np.sin(a), 0])
        est.add_observation(np.r_[0.5 + 0.04 * n[0], 0.04 * n[1], 0.06], n, 1)
    m = est.map_array()
    cand = m[m["kind"] == KIND_CANDIDATE]
    mean, var = est.predict(np.stack([cand["x"], cand["y"]], 1))
    np.testing.assert_allclose(cand["variance"], var)
    assert np.abs(cand["mean"]).max() < 2e-3  # on the zero level set up to interpolation
    lat = m[m["kind"] == KIND_LATTICE]
    mean_l, var_l = est.predict(np.stack([lat["x"], lat["y"]], 1))
    np.testing.assert_allclose(lat["mean"], mean_l, atol=1e-10)
    np.testing.assert_allclose(lat["variance"], var_l, atol=1e-10)


def test_per_contact_noise_down_weights_a_contact():
    p = [0.5, 0.06, 0.06]
    sure, unsure = small_2d(), small_2d()
    assert sure.add_observation(p, None, 1)[0]
    assert unsure.add_observation(p, None, 1, value_var_m2=1e-3)[0]
    assert abs(sure.predict(np.array([p[:2]]))[0][0]) < 1e-4
    _, var_sure = sure.predict(np.array([p[:2]]))
    _, var_unsure = unsure.predict(np.array([p[:2]]))
    assert var_unsure[0] > 100 * var_sure[0]
    assert not unsure.add_observation([0.4, 0.0, 0.06], None, 1, value_var_m2=-1.0)[0]


def test_lattice_inside_agrees_with_the_exact_inside_test():
    """The interpolated inside test (used by the metrics) against the GP's own prediction."""
    est = ShapeEstimator.from_params({"mode": "2d", "lattice.points_per_axis_2d": 96})
    angles = np.linspace(0, 2 * np.pi, 10, endpoint=False)
    for a in angles:
        n = np.array([np.cos(a), np.sin(a), 0.0])
        est.add_observation(np.array([0.5, 0.0, 0.06]) + 0.04 * n, n, 1)
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0.36, 0.64, 20000), rng.uniform(-0.14, 0.14, 20000)])
    exact = est.inside(pts)
    approx = est.lattice_inside(pts)
    assert np.mean(exact != approx) < 0.01  # disagreement only within a lattice cell of the surface
    assert not est.lattice_inside(np.array([[0.0, 0.0], [0.9, 0.9]])).any()


def thin_pole_estimate(r: float, axis: np.ndarray) -> ShapeEstimator:
    """A 3D estimate of a standing pole of radius r (m) at axis (x, y): 11 rings of 8 contacts with
    normals, 3 cm to 13 cm up, each ring turned a little."""
    est = ShapeEstimator.from_params({"mode": "3d"})
    for z in np.linspace(0.03, 0.13, 11):
        for a in np.linspace(0, 2 * np.pi, 8, endpoint=False) + 0.3 * z / 0.01:
            n = np.array([np.cos(a), np.sin(a), 0.0])
            est.add_observation(np.r_[axis + r * n[:2], z], n, 1)
    return est


def test_the_refined_inside_test_keeps_a_thin_pole_the_lattice_shrinks():
    """A standing pole of radius 7 mm on the 48³ lattice (6.4 mm cells): the interpolated lattice mean
    misses much of its section, the refined test (the GP mean within two cells of the surface) agrees
    with the GP's own inside test everywhere, and so with the true pole's section much better."""
    r, axis = 0.007, np.array([0.5, 0.0])
    est = thin_pole_estimate(r, axis)
    g = np.linspace(-0.02, 0.02, 41)
    gx, gy, gz = np.meshgrid(0.5 + g, g, np.linspace(0.05, 0.11, 7), indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    true = np.hypot(pts[:, 0] - axis[0], pts[:, 1] - axis[1]) < r
    exact, refined, lattice = est.inside(pts), est.refined_inside(pts), est.lattice_inside(pts)
    np.testing.assert_array_equal(refined, exact)

    def iou(a, b):
        return np.count_nonzero(a & b) / np.count_nonzero(a | b)

    assert iou(lattice, true) < 0.8 < 0.95 < iou(refined, true)
    far = np.array([[0.40, 0.10, 0.05], [0.5, 0.0, 0.08]])  # far outside, on the axis
    np.testing.assert_array_equal(est.refined_inside(far), [False, True])


def test_a_contact_with_an_unknown_normal_is_a_point_observation():
    """The driver reports a rim contact's normal as NaN: the point counts, the normal does not."""
    p, n = [0.55, 0.0, 0.06], [0.6, 0.8, 0.0]  # a normal the prior circle does not have there
    with_nan, point_only, with_normal = small_2d(), small_2d(), small_2d()
    assert with_nan.add_observation(p, [np.nan] * 3, 1) == (True, "")
    point_only.add_observation(p, None, 1)
    with_normal.add_observation(p, n, 1)
    x = np.random.default_rng(0).uniform([0.4, -0.1], [0.6, 0.1], (50, 2))
    np.testing.assert_array_equal(with_nan.predict(x)[0], point_only.predict(x)[0])
    assert np.abs(with_normal.predict(x)[0] - point_only.predict(x)[0]).max() > 1e-3
    assert with_nan.n_rejected == 0


def test_exported_vertices_lie_on_the_gp_means_zero_crossing():
    """The refined level set against an independent root finder: each vertex is where the GP mean
    crosses zero on its lattice edge (brentq on the same edge), within 0.05 mm; the lattice's own
    vertices (linear in μ along the edge) miss a thin pole's crossings by much more."""
    from scipy.optimize import brentq

    est = thin_pole_estimate(0.007, np.array([0.5, 0.0]))
    raw, fine = est.level_set(), est.refined_level_set()
    assert np.array_equal(raw.keys, fine.keys) and np.array_equal(raw.elements, fine.elements)
    m = len(est._lattice)
    rng = np.random.default_rng(0)
    errors_raw, errors_fine = [], []
    for i in rng.choice(len(raw.keys), 60, replace=False):
        a, b = est._lattice[raw.keys[i] // m], est._lattice[raw.keys[i] % m]
        f = lambda t: est.predict((a + t * (b - a))[None])[0][0]  # noqa: E731
        if f(0.0) * f(1.0) > 0:
            continue  # the GP's own sign agrees at both ends: no crossing to compare with
        root = a + brentq(f, 0.0, 1.0, xtol=1e-9) * (b - a)
        errors_raw.append(np.linalg.norm(raw.vertices[i] - root))
        errors_fine.append(np.linalg.norm(fine.vertices[i] - root))
    assert len(errors_fine) > 40
    assert max(errors_fine) < 5e-5 < 5e-4 < max(errors_raw)
