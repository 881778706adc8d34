"""tactile_common.touch_geometry against the definitions written out by hand."""

import numpy as np
import pytest

from tactile_common.touch_geometry import MotionModel, TouchGeometry, back_off_target, polyline_length_m


def test_a_full_depth_approach_takes_the_skin_max_depth_beyond_the_candidate():
    g = TouchGeometry(tip_radius_m=0.01, standoff_m=0.01, max_depth_m=0.03)
    c, n = np.array([0.5, 0.05, 0.06]), np.array([0.0, 1.0, 0.0])
    p = g.pretouch_xyz(c, n)
    np.testing.assert_allclose(p, [0.5, 0.07, 0.06])  # skin standoff_m off the surface
    end = p - g.approach_length_m * n
    skin_depth = np.dot(c - end, n) + g.tip_radius_m  # how far the leading skin point is below the surface
    assert skin_depth == pytest.approx(g.max_depth_m)


def test_pretouch_points_are_vectorised():
    g = TouchGeometry(0.01, 0.02, 0.03)
    c = np.zeros((4, 3))
    n = np.eye(3)[[0, 1, 2, 0]]
    np.testing.assert_allclose(g.pretouch_xyz(c, n), 0.03 * n)


def test_back_off_leaves_the_skin_standoff_off_the_surface():
    g = TouchGeometry(0.01, 0.01, 0.03)
    contact, tip = np.array([0.5, 0.0, 0.06]), np.array([0.5, 0.009, 0.06])  # tip slightly pressed in
    np.testing.assert_allclose(g.back_off_xyz(contact, tip), [0.5, 0.02, 0.06])
    assert back_off_target(contact, contact, 0.02) is None
    assert back_off_target(np.full(3, np.nan), tip, 0.02) is None


def test_time_of_a_touch():
    m = MotionModel(tip_speed_mps=0.1, approach_speed_mps=0.02, dwell_s=0.5)
    assert m.touch_time_s(0.3, 0.01) == pytest.approx(3.0 + 1.0 + 0.5)
    assert m.path_contact_time_s(0.2, 0.02) == pytest.approx(2.0 + 1.0)
    assert polyline_length_m(np.array([[0, 0, 0], [3, 4, 0], [3, 4, 1.0]])) == pytest.approx(6.0)
    assert TouchGeometry.from_params({"standoff_m": 0.02, "unrelated": 1}).standoff_m == 0.02
