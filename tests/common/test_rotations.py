"""tactile_common.rotations against scipy's Rotation and against hand-computed rotations."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tactile_common.rotations import matrix_to_quaternion, quaternion_to_matrix, quaternion_x_axis, xyzw


def _canonical(q):
    q = np.asarray(q, float)
    return np.where(q[..., 3:] < 0, -q, q)


def _hard_rotations():
    """Identity, 180° turns about axes and diagonals (w = 0, trace = −1) and near them."""
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, -1, 1], [0, 1, -1]], float)
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.array([0.0, np.pi, np.pi - 1e-7, 1e-7, np.pi / 2])
    return Rotation.from_rotvec((axes[:, None, :] * angles[None, :, None]).reshape(-1, 3))


def test_quaternion_to_matrix_matches_scipy_for_random_and_unnormalised_quaternions():
    q = Rotation.random(200, random_state=1).as_quat() * np.random.default_rng(2).uniform(0.1, 5.0, (200, 1))
    np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_quat(q).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix(q[7]), Rotation.from_quat(q[7]).as_matrix(), atol=1e-12)


@pytest.mark.parametrize("rotations", [Rotation.random(200, random_state=3), _hard_rotations()])
def test_matrix_to_quaternion_matches_scipy_with_w_non_negative(rotations):
    rot = rotations.as_matrix()
    q = matrix_to_quaternion(rot)
    assert q.shape == (len(rot), 4) and np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    ref = _canonical(Rotation.from_matrix(rot).as_quat())
    # at w = 0, q and −q both have w ≥ 0: compare the rotations there
    same = np.minimum(np.abs(q - ref).max(axis=1), np.abs(q + ref).max(axis=1))
    assert same.max() < 1e-9
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), rot, atol=1e-12)


def test_convention_by_hand_quarter_turn_about_z_takes_x_to_y():
    q = [0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)]  # +90° about z
    tip_to_world = quaternion_to_matrix(q)
    np.testing.assert_allclose(tip_to_world @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(quaternion_x_axis(q), [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(matrix_to_quaternion([[0, -1, 0], [1, 0, 0], [0, 0, 1]]), q, atol=1e-15)


def test_xyzw_reads_message_fields():
    class Quaternion:  # stands in for geometry_msgs/Quaternion
        x, y, z, w = 0.1, 0.2, 0.3, 0.9

    np.testing.assert_array_equal(xyzw(Quaternion()), [0.1, 0.2, 0.3, 0.9])


@pytest.mark.parametrize("q, match", [
    ([0.0, 0.0, 0.0, 0.0], "finite and non-zero"),
    ([np.nan, 0.0, 0.0, 1.0], "finite and non-zero"),
    ([0.0, 0.0, 1.0], r"shape \(\.\.\., 4\)"),
])
def test_bad_quaternions_raise_one_line(q, match):
    with pytest.raises(ValueError, match=match):
        quaternion_to_matrix(q)


@pytest.mark.parametrize("m, match", [
    (np.diag([1.0, 1.0, -1.0]), "not a rotation"),
    (2 * np.eye(3), "not a rotation"),
    (np.full((3, 3), np.nan), "finite"),
    (np.eye(2), r"shape \(\.\.\., 3, 3\)"),
])
def test_bad_matrices_raise_one_line(m, match):
    with pytest.raises(ValueError, match=match):
        matrix_to_quaternion(m)
