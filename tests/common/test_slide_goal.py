"""A slide goal's encoding (tactile_common.slide_goal): round trip, pokes untouched, bad input."""

import numpy as np
import pytest

from tactile_common.rotations import matrix_to_quaternion, quaternion_to_matrix
from tactile_common.slide_goal import decode_path, encode_path, slide_rotation


def test_a_slide_goal_round_trips_through_the_path_and_the_orientation():
    rng = np.random.default_rng(3)
    for _ in range(20):
        path = rng.uniform(0.3, 0.6, (int(rng.integers(1, 6)), 3))
        goal = path[-1].copy()
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = np.cross([0.0, 0.0, 1.0], n)
        d /= np.linalg.norm(d)
        length = float(rng.uniform(0.02, 0.6))
        enc = encode_path(path, goal, 2.5 * d, length)  # any scale of the direction
        assert enc.shape == (len(path) + 1, 3)
        dec = decode_path(enc, goal)
        assert dec.is_slide and dec.slide_length_m == pytest.approx(length, abs=1e-12)
        np.testing.assert_allclose(dec.slide_direction_xyz, d, atol=1e-12)
        np.testing.assert_array_equal(dec.free_path_xyz, path)
        # the orientation: x = approach (−n), y = the direction, right-handed; survives a quaternion
        R = quaternion_to_matrix(matrix_to_quaternion(slide_rotation(-n, d)))
        np.testing.assert_allclose(R[:, 0], -n, atol=1e-9)
        np.testing.assert_allclose(R[:, 1], d, atol=1e-9)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
        assert np.linalg.det(R) == pytest.approx(1.0)


def test_a_poke_path_is_never_a_slide():
    path = np.array([[0.35, 0.0, 0.06], [0.40, 0.02, 0.06], [0.42, 0.03, 0.06]])
    dec = decode_path(path, path[-1])
    assert not dec.is_slide and np.isnan(dec.slide_length_m)
    np.testing.assert_array_equal(dec.free_path_xyz, path)
    # a path that does not end at the goal (the commander appends the pre-touch point) is no slide either
    assert not decode_path(path, np.array([0.5, 0.0, 0.06])).is_slide
    assert not decode_path(path[:1], path[0]).is_slide


def test_encode_appends_the_goal_when_the_path_does_not_end_there():
    enc = encode_path(np.array([[0.3, 0.0, 0.06]]), np.array([0.4, 0.0, 0.06]), np.array([0.0, 1.0, 0.0]), 0.1)
    np.testing.assert_allclose(enc, [[0.3, 0, 0.06], [0.4, 0, 0.06], [0.4, 0.1, 0.06]])


@pytest.mark.parametrize("direction, length", [([0, 0, 0], 0.1), ([0, 1, 0], 0.0), ([0, 1, 0], np.nan),
                                               ([np.nan, 1, 0], 0.1)])
def test_bad_slides_are_refused_in_one_line(direction, length):
    with pytest.raises(ValueError, match="slide goal"):
        encode_path(np.zeros((1, 3)), np.zeros(3), np.array(direction, float), length)


def test_a_direction_along_the_approach_has_no_rotation():
    with pytest.raises(ValueError, match="not along the approach"):
        slide_rotation(np.array([1.0, 0, 0]), np.array([2.0, 0, 0]))
