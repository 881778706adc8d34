"""A miss's sweep (free_space.sweep_step_m): the free-space rows along the segment the finger swept.
Oracle: the same estimator fed those points one by one as plain free-space observations."""

import numpy as np
import pytest

from tactile_gpis.estimator import ShapeEstimator


def _est(**over) -> ShapeEstimator:
    return ShapeEstimator.from_params({"mode": "2d", "free_space.sweep_step_m": 0.01, **over})


def test_a_sweep_adds_the_points_the_finger_passed():
    end = np.array([0.47, 0.01, 0.06])
    sweep = np.array([-0.035, 0.0, 0.0])  # the approach began 35 mm to the left
    a = _est()
    assert a.add_observation(end, sweep, 0) == (True, "")
    b = _est()
    b.add_observation(end, None, 0)
    for t in (0.01, 0.02, 0.03):  # every 10 mm back along the sweep, not beyond its start
        b.add_observation(end + t / 0.035 * sweep, None, 0)
    q = np.random.default_rng(0).uniform([0.36, -0.14], [0.64, 0.14], size=(50, 2))
    for (ma, va), (mb, vb) in [(a.predict(q), b.predict(q))]:
        np.testing.assert_allclose(ma, mb, atol=1e-12)
        np.testing.assert_allclose(va, vb, atol=1e-12)
    assert a.n_observations == 1 and b.n_observations == 4  # one observation, four rows


@pytest.mark.parametrize("sweep", [None, np.zeros(3), np.array([np.nan, 0.0, 0.0])])
def test_no_sweep_is_the_point_alone(sweep):
    end = np.array([0.47, 0.01, 0.06])
    a, b = _est(), _est()
    a.add_observation(end, sweep if sweep is None or np.isfinite(sweep).all() else None, 0)
    b.add_observation(end, None, 0)
    q = np.array([[0.45, 0.0], [0.5, 0.05]])
    np.testing.assert_allclose(a.predict(q)[0], b.predict(q)[0], atol=1e-12)


def test_sweep_off_and_sweep_rows_near_earlier_points_are_skipped():
    end = np.array([0.47, 0.01, 0.06])
    sweep = np.array([-0.035, 0.0, 0.0])
    off = _est(**{"free_space.sweep_step_m": 0.0})
    off.add_observation(end, sweep, 0)
    plain = _est()
    plain.add_observation(end, None, 0)
    q = np.array([[0.45, 0.0], [0.5, 0.05]])
    np.testing.assert_allclose(off.predict(q)[0], plain.predict(q)[0], atol=1e-12)
    # a second miss along the same line adds nothing new where the first one swept
    twice = _est()
    twice.add_observation(end, sweep, 0)
    twice.add_observation(end + np.array([0.0005, 0, 0]), sweep, 0)  # within duplicate_distance_m: rejected
    once = _est()
    once.add_observation(end, sweep, 0)
    np.testing.assert_allclose(twice.predict(q)[0], once.predict(q)[0], atol=1e-12)
