"""Fingertip poses over a short time window, interpolated at a sensor frame's time (ROS-free).

Position: linear interpolation; orientation: quaternion slerp. A query time
outside the buffered span by at most ``tolerance_s`` uses the nearest pose;
further outside (or an empty buffer) gives None: no contact may be published
without a fingertip pose at its time. Inside the span, two poses more than
``max_gap_s`` apart do not interpolate (None): the stream stalled there, and a
straight line between them is not where the finger was.
"""

from __future__ import annotations

from collections import deque
from typing import Optional

import numpy as np

from tactile_common.rotations import quaternion_to_matrix


def slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions, shortest arc, u in [0, 1]."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    dot = float(q0 @ q1)
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(dot)
    return (np.sin((1 - u) * theta) * q0 + np.sin(u * theta) * q1) / np.sin(theta)


class PoseBuffer:
    """Time-ordered fingertip poses (world frame) of the last ``max_age_s`` seconds."""

    def __init__(self, max_age_s: float = 2.0, tolerance_s: float = 0.02, max_gap_s: float = 0.1) -> None:
        if max_age_s <= 0 or tolerance_s < 0 or max_gap_s <= 0:
            raise ValueError("need max_age_s > 0, tolerance_s >= 0 and max_gap_s > 0")
        self.max_age_s = max_age_s
        self.tolerance_s = tolerance_s
        self.max_gap_s = max_gap_s
        self._t: deque[float] = deque()
        self._p: deque[np.ndarray] = deque()
        self._q: deque[np.ndarray] = deque()
        self.rejected = 0  # out-of-order or invalid poses

    def __len__(self) -> int:
        return len(self._t)

    def add(self, t_s: float, position_m: np.ndarray, q_xyzw: np.ndarray) -> bool:
        """Append a pose; False (and counted) if it is older than the newest or not finite."""
        p, q = np.asarray(position_m, float), np.asarray(q_xyzw, float)
        norm = float(np.linalg.norm(q))
        if not (np.all(np.isfinite(p)) and np.isfinite(norm) and norm > 1e-6) or (self._t and t_s < self._t[-1]):
            self.rejected += 1
            return False
        self._t.append(float(t_s))
        self._p.append(p)
        self._q.append(q / norm)
        while self._t and self._t[0] < t_s - self.max_age_s:
            self._t.popleft()
            self._p.popleft()
            self._q.popleft()
        return True

    @property
    def newest_s(self) -> Optional[float]:
        return self._t[-1] if self._t else None

    def clear(self) -> None:
        self._t.clear()
        self._p.clear()
        self._q.clear()

    def at(self, t_s: float) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """(position, rotation matrix) at ``t_s``, or None when no pose covers that time."""
        if not self._t or t_s < self._t[0] - self.tolerance_s or t_s > self._t[-1] + self.tolerance_s:
            return None
        times = np.fromiter(self._t, float, len(self._t))
        i = int(np.searchsorted(times, t_s))
        if i == 0:
            return self._p[0].copy(), quaternion_to_matrix(self._q[0])
        if i >= len(times):
            return self._p[-1].copy(), quaternion_to_matrix(self._q[-1])
        t0, t1 = times[i - 1], times[i]
        if t1 - t0 > self.max_gap_s:  # the stream stalled here: only a pose within tolerance counts
            if t_s - t0 <= self.tolerance_s:
                return self._p[i - 1].copy(), quaternion_to_matrix(self._q[i - 1])
            if t1 - t_s <= self.tolerance_s:
                return self._p[i].copy(), quaternion_to_matrix(self._q[i])
            return None
        u = 0.0 if t1 <= t0 else (t_s - t0) / (t1 - t0)
        p = (1 - u) * self._p[i - 1] + u * self._p[i]
        return p, quaternion_to_matrix(slerp(self._q[i - 1], self._q[i], u))
