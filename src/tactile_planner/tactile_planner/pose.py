"""Goal orientation of the pre-touch pose (world frame)."""

from __future__ import annotations

import numpy as np

from tactile_common.rotations import matrix_to_quaternion


def approach_rotation(normal_xyz: np.ndarray) -> np.ndarray:
    """Rotation matrix (columns = goal x, y, z axes in world) with x = −n (the approach
    direction) and z as close to world +z as possible (z = normalised projection of
    +z orthogonal to x; world x or y is used if the approach is vertical)."""
    n = np.asarray(normal_xyz, float)
    x = -n / np.linalg.norm(n)
    for up in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        z = up - np.dot(up, x) * x
        if np.linalg.norm(z) > 1e-6:
            break
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


# The goal quaternion: tactile_common.rotations (one convention); the old name stays for callers.
quaternion_xyzw = matrix_to_quaternion
