"""The finger axis on a goal's path: the frame, its decoding, the tilted tail."""

import numpy as np
import pytest

from tactile_common.finger_axis import axes_from_quaternions, finger_frame, tilted_tail
from tactile_common.rotations import matrix_to_quaternion

Z = [0.0, 0.0, 1.0]


def test_the_frame_has_the_axis_as_z_and_the_approach_as_x_where_it_can():
    a = np.array([np.sin(1.0), 0.0, np.cos(1.0)])
    R = finger_frame([0.0, 1.0, 0.0], a)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], a)
    np.testing.assert_allclose(R[:, 0], [0.0, 1.0, 0.0], atol=1e-12)  # already orthogonal to a
    # a vertical finger approaching from above: any x orthogonal to z (world x)
    np.testing.assert_allclose(finger_frame([0.0, 0.0, -1.0], Z), np.eye(3), atol=1e-12)
    with pytest.raises(ValueError, match="finger axis"):
        finger_frame([1.0, 0, 0], [0.0, 0.0, 0.0])


def test_quaternions_decode_to_their_z_axes_and_an_empty_one_is_vertical():
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(5, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    q = np.array([matrix_to_quaternion(finger_frame(rng.normal(size=3), a)) for a in axes])
    np.testing.assert_allclose(axes_from_quaternions(q * 3.0), axes, atol=1e-12)  # not normalised: fine
    np.testing.assert_allclose(axes_from_quaternions(np.zeros((2, 4))), [Z, Z])
    np.testing.assert_allclose(axes_from_quaternions([[np.nan, 0, 0, 1]]), [Z])


def test_the_tail_is_where_the_finger_turns_and_the_axis_it_keeps():
    a = np.array([0.0, -np.sin(1.2), np.cos(1.2)])
    P = np.array([[0.4, 0.0, 0.2], [0.5, 0.1, 0.1], [0.5, 0.1, 0.1], [0.5, 0.05, 0.08]])
    A = np.array([Z, Z, a, a])
    tail = tilted_tail(P, A, 0.1)
    np.testing.assert_allclose(tail.entry_xyz, P[1])
    np.testing.assert_allclose(tail.axis_xyz, a)
    assert tilted_tail(P, np.array([Z] * 4), 0.1) is None
    assert tilted_tail(P, np.array([Z, Z, Z, [0.05, 0, 1.0]]) / [[1], [1], [1], [np.hypot(0.05, 1)]], 0.1) is None


@pytest.mark.parametrize("axes, match", [
    ([Z, [0, 1.0, 0], Z, Z], "inside the path"),
    ([Z, Z, [0, 1.0, 0], [1.0, 0, 0]], "share one finger axis"),
    ([[0, 1.0, 0]] * 4, "no pose with the vertical finger"),
])
def test_a_tail_not_of_that_form_is_refused_with_the_reason(axes, match):
    P = np.array([[0.4, 0.0, 0.2], [0.5, 0.1, 0.1], [0.5, 0.1, 0.1], [0.5, 0.05, 0.08]])
    with pytest.raises(ValueError, match=match):
        tilted_tail(P, np.array(axes, float), 0.1)
    with pytest.raises(ValueError, match="repeat the last vertical"):
        tilted_tail(P[[0, 1, 3, 3]], np.array([Z, Z, [0, 1.0, 0], [0, 1.0, 0]]), 0.1)
