"""Emulation of ros2_control's joint_trajectory_controller (topic interface), perfect tracking.

Semantics kept from ros2_control:
- a new trajectory replaces the current one from the moment it arrives
  (header stamp 0) or from its stamp (if later); before its start the arm
  holds; the current state is the first knot unless the first point has
  ``time_from_start`` 0;
- positions + velocities: cubic Hermite interpolation between points;
  positions only: linear; after the last point the arm holds it;
- an empty trajectory stops and holds the current position;
- joint names may come in any order but must cover every controlled joint;
  bad trajectories (missing joints, wrong sizes, non-increasing times,
  NaN) are rejected with a reason and the current motion continues.
The measured state is the commanded one (no tracking error).
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np


class TrajectoryRejected(ValueError):
    """A trajectory message the controller refuses, with the reason."""


class TrajectoryController:
    """Joint positions and velocities over (simulated) time, in ``joint_names`` order."""

    def __init__(self, joint_names: Sequence[str], q0: np.ndarray) -> None:
        self.joint_names = list(joint_names)
        q0 = np.asarray(q0, dtype=float)
        if q0.shape != (len(self.joint_names),):
            raise ValueError(f"initial state needs {len(self.joint_names)} values, got {q0.shape}")
        self._t = np.array([0.0])
        self._q = q0[None].copy()
        self._qd = np.zeros_like(self._q)
        self._cubic = False
        self.accepted = 0
        self.rejected = 0

    def command(self, now_s: float, joint_names: Sequence[str], times_s: np.ndarray, positions: np.ndarray,
                velocities: Optional[np.ndarray] = None, start_s: float = 0.0) -> None:
        """Replace the trajectory (times from ``start_s``, or from ``now_s`` when 0 / past).

        Raises:
            TrajectoryRejected: the message is inconsistent (nothing changes).
        """
        q_now, qd_now = self.state(now_s)
        times = np.asarray(times_s, dtype=float).reshape(-1)
        if len(times) == 0:  # stop: hold the current position
            self._set(np.array([now_s]), q_now[None], np.zeros((1, len(q_now))), cubic=False)
            self.accepted += 1
            return
        try:
            order = [list(joint_names).index(j) for j in self.joint_names]
        except ValueError:
            self.rejected += 1
            raise TrajectoryRejected(f"trajectory joints {list(joint_names)} do not cover {self.joint_names}") from None
        pos = np.asarray(positions, dtype=float)
        vel = None if velocities is None else np.asarray(velocities, dtype=float)
        if pos.shape != (len(times), len(joint_names)) or (vel is not None and vel.shape != pos.shape):
            self.rejected += 1
            raise TrajectoryRejected(f"every point needs {len(joint_names)} positions (and velocities if any)")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(times)) and (vel is None or np.all(np.isfinite(vel)))):
            self.rejected += 1
            raise TrajectoryRejected("trajectory contains NaN or inf")
        if np.any(np.diff(times) <= 0) or times[0] < 0:
            self.rejected += 1
            raise TrajectoryRejected("time_from_start must be non-negative and strictly increasing")
        pos = pos[:, order]
        vel = np.zeros_like(pos) if vel is None else vel[:, order]
        t0 = max(float(start_s), float(now_s))
        t, q, qd = t0 + times, pos, vel
        if times[0] > 1e-9:  # interpolate from the current state
            t = np.concatenate([[t0], t])
            q = np.vstack([q_now[None], q])
            qd = np.vstack([qd_now[None] if t0 <= now_s else np.zeros((1, len(q_now))), qd])
        if t0 > now_s:  # hold until the start
            t, q, qd = np.concatenate([[now_s], t]), np.vstack([q_now[None], q]), np.vstack([np.zeros((1, len(q_now))), qd])
        self._set(t, q, qd, cubic=velocities is not None)
        self.accepted += 1

    def _set(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, cubic: bool) -> None:
        self._t, self._q, self._qd, self._cubic = t, q, qd, cubic

    def state(self, now_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded (= measured) joint positions and velocities at ``now_s``."""
        t, q = self._t, self._q
        if now_s <= t[0]:
            return q[0].copy(), (self._qd[0].copy() if len(t) > 1 and now_s == t[0] else np.zeros(q.shape[1]))
        if now_s >= t[-1]:
            return q[-1].copy(), np.zeros(q.shape[1])
        k = int(np.searchsorted(t, now_s, side="right") - 1)
        h = t[k + 1] - t[k]
        s = (now_s - t[k]) / h
        q0, q1 = q[k], q[k + 1]
        if not self._cubic:
            return q0 + s * (q1 - q0), (q1 - q0) / h
        v0, v1 = self._qd[k] * h, self._qd[k + 1] * h
        pos = (2 * s**3 - 3 * s**2 + 1) * q0 + (s**3 - 2 * s**2 + s) * v0 + (-2 * s**3 + 3 * s**2) * q1 + (s**3 - s**2) * v1
        vel = ((6 * s**2 - 6 * s) * q0 + (3 * s**2 - 4 * s + 1) * v0 + (-6 * s**2 + 6 * s) * q1 + (3 * s**2 - 2 * s) * v1) / h
        return pos, vel

    @property
    def end_s(self) -> float:
        return float(self._t[-1])
