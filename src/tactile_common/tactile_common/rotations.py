"""Rotations: unit quaternion (x, y, z, w) <-> rotation matrix, one convention (numpy only).

Convention (ROS ``geometry_msgs/Quaternion``, Eigen, scipy ``Rotation.from_quat``):
a Hamilton quaternion with the scalar last, q = (sin(θ/2)·u, cos(θ/2)) for a
rotation by θ about the unit axis u. Its matrix ``rot_b_to_a`` maps a vector
given in frame b to frame a (v_a = R v_b); its columns are b's axes expressed
in a — e.g. ``tip_to_world``, whose first column is the fingertip's x-axis in
the world frame. With v = (x, y, z): R = I + 2w[v]× + 2[v]×².

q and −q are the same rotation; ``matrix_to_quaternion`` returns w ≥ 0.
Every function takes one item or a stack (leading dimensions broadcast).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Largest ‖RᵀR − I‖ (max abs entry) accepted as a rotation matrix.
ORTHONORMAL_TOL = 1e-6


def xyzw(q: Any) -> np.ndarray:
    """The (4,) array (x, y, z, w) of an object with fields x, y, z, w (e.g. a Quaternion message)."""
    return np.array([q.x, q.y, q.z, q.w], dtype=float)


def quaternion_to_matrix(q_xyzw: Any) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) given as (x, y, z, w).

    The quaternion is normalised first; a zero or non-finite one raises ValueError.
    """
    q = np.asarray(q_xyzw, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion must have shape (..., 4) as (x, y, z, w); got shape {q.shape}")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(norm)) or np.any(norm < 1e-9):
        raise ValueError(f"quaternion (x, y, z, w) must be finite and non-zero; got {q.tolist()}")
    x, y, z, w = np.moveaxis(q / norm, -1, 0)
    rot = np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    ], axis=-1)
    return rot.reshape(q.shape[:-1] + (3, 3))


def quaternion_x_axis(q_xyzw: Any) -> np.ndarray:
    """First column (..., 3) of the rotation of ``q_xyzw``: the rotated frame's x-axis in the parent frame."""
    return quaternion_to_matrix(q_xyzw)[..., :, 0]


def matrix_to_quaternion(rot: Any) -> np.ndarray:
    """Unit quaternions (..., 4) as (x, y, z, w), w ≥ 0, of rotation matrices (..., 3, 3).

    Shepperd's method: of 4x², 4y², 4z², 4w² (linear in the diagonal) the largest
    gives the component computed by a square root, the other three follow from
    the off-diagonal sums/differences; stable for every rotation, 180° included.
    Raises ValueError for a matrix that is not a rotation (orthonormal, det +1,
    within ``ORTHONORMAL_TOL``).
    """
    m = np.asarray(rot, dtype=float)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrix must have shape (..., 3, 3); got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("rotation matrix must be finite; got NaN or inf entries")
    err = np.abs(np.swapaxes(m, -1, -2) @ m - np.eye(3)).max(initial=0.0)
    if err > ORTHONORMAL_TOL or np.any(np.linalg.det(m) < 0):
        raise ValueError(f"matrix is not a rotation (|RᵀR − I| = {err:.2g}, allowed {ORTHONORMAL_TOL:g}, det must be +1)")
    r = lambda i, j: m[..., i, j]  # noqa: E731
    d0, d1, d2 = r(0, 0), r(1, 1), r(2, 2)
    # Row k: 4·q·q_k for the case where q_k is the largest component.
    cases = np.stack([
        np.stack([1 + d0 - d1 - d2, r(0, 1) + r(1, 0), r(0, 2) + r(2, 0), r(2, 1) - r(1, 2)], axis=-1),
        np.stack([r(0, 1) + r(1, 0), 1 - d0 + d1 - d2, r(1, 2) + r(2, 1), r(0, 2) - r(2, 0)], axis=-1),
        np.stack([r(0, 2) + r(2, 0), r(1, 2) + r(2, 1), 1 - d0 - d1 + d2, r(1, 0) - r(0, 1)], axis=-1),
        np.stack([r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1), 1 + d0 + d1 + d2], axis=-1),
    ], axis=-2)
    k = np.argmax(np.stack([1 + d0 - d1 - d2, 1 - d0 + d1 - d2, 1 - d0 - d1 + d2, 1 + d0 + d1 + d2], axis=-1),
                  axis=-1)
    q = np.take_along_axis(cases, k[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:] < 0, -q, q)
