"""Goal orientation of the pre-touch pose (world frame)."""

from __future__ import annotations

import numpy as np


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


def quaternion_xyzw(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method), w ≥ 0."""
    m = np.asarray(rot, float)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = np.zeros(4)
        q[i] = 0.25 * s
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
        q[3] = (m[k, j] - m[j, k]) / s
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q
