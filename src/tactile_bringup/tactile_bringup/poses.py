"""Small pose helpers for messages' quaternions (x, y, z, w), numpy only."""

from __future__ import annotations

import numpy as np


def pose_x_axis(q) -> np.ndarray:
    """The x-axis (first column of the rotation) of a quaternion with fields x, y, z, w."""
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)])
