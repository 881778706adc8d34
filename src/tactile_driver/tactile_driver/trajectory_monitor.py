"""Independent check of a joint trajectory sent to the controller (ROS-free).

A monitor for tests and for a safety watch: given what the commander
published (joint names, times, positions, velocities) it rebuilds the motion
the controller executes and reports every place it breaks a limit. The
limits are the commander's own objects (:class:`~tactile_driver.trajectory.
MotionLimits`, :class:`~tactile_driver.safety.WorkspaceBox`, the tip by
:meth:`~tactile_driver.kinematics.ArmModel.fk`); the motion is rebuilt with
scipy, not with the planner's code:

- positions + velocities: a cubic Hermite spline
  (``scipy.interpolate.CubicHermiteSpline``, what ros2_control's
  joint_trajectory_controller executes). On segment k, with local time
  τ ∈ [0, h_k], q(τ) = c0 τ³ + c1 τ² + c2 τ + c3 (scipy's coefficients), so
  exactly: acceleration 6 c0 τ + 2 c1 is extreme at the segment's ends;
  velocity 3 c0 τ² + 2 c1 τ + c2 at the ends or at τ* = −c1 / (3 c0);
  position at the ends or at the real roots of the velocity in (0, h_k).
- the tip (world frame) is checked against the box at every knot and at
  ``samples_per_segment`` points inside each segment (FK is not polynomial),
  grown by ``box_slack_m``: the commander lets IK waypoints lie up to its
  ``ik_tol_m`` outside (a point planned on a face, e.g. the box floor), so a
  monitor of the commander uses that (``commander_monitor`` in the tests).
- a first point at ``time_from_start`` 0 must equal the measured state
  (within ``start_tolerance_rad``): the controller would jump to it; a later
  first point makes the measured state the first knot, at rest or, when the
  measured velocity is given, moving at it (a replacing trajectory sent while
  the arm moves: the controller interpolates from its current state).
- an empty trajectory (stop and hold) is always safe; positions without
  velocities (linear interpolation: an unbounded acceleration at every
  knot) and malformed messages are violations.

Limits hold up to a relative ``tolerance`` (the planner meets them exactly,
up to rounding).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from tactile_driver.kinematics import ArmModel
from tactile_driver.safety import WorkspaceBox
from tactile_driver.trajectory import MotionLimits


@dataclass(frozen=True)
class Violation:
    """One broken rule: ``kind`` (position, velocity, acceleration, workspace, start, malformed),
    the joint ('' for the tip or the whole message), the time from start (s), the value and the limit."""

    kind: str
    joint: str
    time_s: float
    value: float
    limit: float
    detail: str = ""

    def __str__(self) -> str:
        who = f" {self.joint}" if self.joint else ""
        text = f"{self.kind}{who} at t={self.time_s:.3f} s: {self.value:.6g} beyond {self.limit:.6g} {self.detail}"
        return text.strip()


class TrajectoryMonitor:
    """Checks trajectories against joint limits and the tip's workspace box (see the module docstring)."""

    def __init__(self, model: ArmModel, limits: MotionLimits, box: WorkspaceBox, samples_per_segment: int = 8,
                 tolerance: float = 1e-6, start_tolerance_rad: float = 0.01, box_slack_m: float = 0.0) -> None:
        if samples_per_segment < 0 or tolerance < 0 or start_tolerance_rad < 0 or not box_slack_m >= 0:
            raise ValueError("samples_per_segment, tolerance, start_tolerance_rad and box_slack_m must be >= 0")
        self.box_slack_m = float(box_slack_m)
        self.model, self.limits, self.box = model, limits, box
        self.samples_per_segment = int(samples_per_segment)
        self.tolerance = float(tolerance)
        self.start_tolerance_rad = float(start_tolerance_rad)
        self.checked = 0  # trajectories checked
        self.violations: list[Violation] = []  # all found so far

    @classmethod
    def from_params(cls, model: ArmModel, velocity_rad_s: Sequence[float], acceleration_rad_s2: Sequence[float],
                    box_x_m: Sequence[float], box_y_m: Sequence[float], box_z_m: Sequence[float],
                    table_z_m: float = 0.0, table_margin_m: float = 0.005, tip_radius_m: float = 0.010,
                    tip_speed_mps: float = 0.10, **kwargs) -> "TrajectoryMonitor":
        """The monitor for the arm_commander parameters of the same names (its YAML file)."""
        limits = MotionLimits.for_model(model, velocity_rad_s, acceleration_rad_s2, tip_speed_mps)
        box = WorkspaceBox.from_params(box_x_m, box_y_m, box_z_m, table_z_m, table_margin_m, tip_radius_m)
        return cls(model, limits, box, **kwargs)

    def check(self, joint_names: Sequence[str], times_s: Sequence[float], positions_rad, velocities_rad_s=None,
              q_now: Optional[np.ndarray] = None, qd_now: Optional[np.ndarray] = None) -> list[Violation]:
        """Violations of one trajectory (empty: safe); also appended to :attr:`violations`.

        Args:
            joint_names: the message's joint order (any order of the model's joints).
            times_s: (K,) time from start of each point.
            positions_rad: (K, n) positions in ``joint_names`` order.
            velocities_rad_s: (K, n), or None / empty for positions-only points.
            q_now: the measured joints (model order) when the trajectory was sent, if known.
            qd_now: the measured joint velocities then (model order); None: at rest.
        """
        found = self._check(list(joint_names), times_s, positions_rad, velocities_rad_s, q_now, qd_now)
        self.checked += 1
        self.violations.extend(found)
        return found

    # -- internals -------------------------------------------------------------
    def _check(self, names, times_s, positions, velocities, q_now, qd_now=None) -> list[Violation]:
        t = np.asarray(times_s, dtype=float).reshape(-1)
        if len(t) == 0:
            return []  # stop and hold
        nq = self.model.nq
        if sorted(names) != sorted(self.model.joint_names) or len(set(names)) != nq:
            return [_bad(f"joint names {names}, expected the set {list(self.model.joint_names)}")]
        perm = [names.index(j) for j in self.model.joint_names]
        try:
            q = np.asarray(positions, dtype=float).reshape(len(t), -1)
            qd = None if velocities is None or np.size(velocities) == 0 else np.asarray(velocities, dtype=float)
        except ValueError as exc:  # ragged: points with different numbers of values
            return [_bad(f"positions or velocities do not form a (K, n) array: {exc}")]
        if q.shape != (len(t), nq):
            return [_bad(f"positions have shape {q.shape}, expected {(len(t), nq)}")]
        if qd is not None and qd.shape != q.shape:
            return [_bad(f"velocities have shape {qd.shape}, expected {q.shape}")]
        if not (np.isfinite(t).all() and np.isfinite(q).all() and (qd is None or np.isfinite(qd).all())):
            return [_bad("times, positions or velocities not finite")]
        if t[0] < 0 or np.any(np.diff(t) <= 0):
            return [_bad(f"times must be >= 0 and increasing, got {t.tolist()[:6]}")]
        q = q[:, perm]
        qd = qd[:, perm] if qd is not None else None
        out: list[Violation] = []
        if q_now is not None:
            q_now = np.asarray(q_now, dtype=float)
            if t[0] == 0.0:
                jump = np.abs(q[0] - q_now)
                j = int(np.argmax(jump))
                if jump[j] > self.start_tolerance_rad:
                    out.append(Violation("start", self.model.joint_names[j], 0.0, float(jump[j]),
                                         self.start_tolerance_rad, "rad from the measured state"))
            else:  # the controller starts from the measured state (at rest unless its velocity is given)
                t, q = np.r_[0.0, t], np.vstack([q_now[None], q])
                v0 = np.zeros((1, nq)) if qd_now is None else np.asarray(qd_now, dtype=float).reshape(1, nq)
                qd = np.vstack([v0, qd]) if qd is not None else None
        if len(t) == 1:
            return out + self._positions(t, q) + self._workspace(t, q)
        if qd is None:
            return out + [_bad("positions without velocities: linear interpolation, unbounded acceleration")]
        spline = CubicHermiteSpline(t, q, qd)
        out += self._spline_limits(spline)
        tau = np.linspace(0.0, 1.0, self.samples_per_segment + 2)[:-1]
        ts = np.r_[(t[:-1, None] + np.diff(t)[:, None] * tau[None]).ravel(), t[-1]]
        return out + self._workspace(ts, spline(ts))

    def _spline_limits(self, spline: CubicHermiteSpline) -> list[Violation]:
        c0, c1, c2, c3 = spline.c  # each (m, n): segment, joint
        zero = np.zeros_like(c0)
        h = zero + np.diff(spline.x)[:, None]
        t0 = spline.x[:-1, None]
        # acceleration 6 c0 τ + 2 c1: extreme at the ends
        acc, acc_t = np.stack([2 * c1, 6 * c0 * h + 2 * c1]), np.stack([zero, h])
        # velocity 3 c0 τ² + 2 c1 τ + c2: the ends, and τ* = -c1 / (3 c0) if inside
        with np.errstate(divide="ignore", invalid="ignore"):
            tv = np.where(c0 != 0, -c1 / (3 * c0), 0.0)
        tv = np.where((tv > 0) & (tv < h), tv, 0.0)
        vel_t = np.stack([zero, h, tv])
        vel = 3 * c0 * vel_t**2 + 2 * c1 * vel_t + c2
        # position: the ends, and the real roots of the velocity inside the segment
        a, b = 3 * c0, 2 * c1
        disc = b**2 - 4 * a * c2
        root = np.sqrt(np.maximum(disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            linear = np.where(b != 0, -c2 / b, 0.0)
            r1 = np.where(a != 0, (-b + root) / (2 * a), linear)
            r2 = np.where(a != 0, (-b - root) / (2 * a), linear)
        roots = [np.where((disc >= 0) & (r > 0) & (r < h), r, 0.0) for r in (r1, r2)]
        pos_t = np.stack([zero, h, *roots])
        pos = ((c0 * pos_t + c1) * pos_t + c2) * pos_t + c3
        lim = self.limits
        return (self._exceed("velocity", np.abs(vel), vel_t + t0, lim.velocity_rad_s, "rad/s")
                + self._exceed("acceleration", np.abs(acc), acc_t + t0, lim.acceleration_rad_s2, "rad/s²")
                + self._exceed("position", pos - lim.upper_rad, pos_t + t0, 0.0, "rad above the upper limit",
                               absolute=True)
                + self._exceed("position", lim.lower_rad - pos, pos_t + t0, 0.0, "rad below the lower limit",
                               absolute=True))

    def _exceed(self, kind, value, when, limit, unit, absolute=False) -> list[Violation]:
        """The worst violation per joint (value > limit (1 + tolerance), or > tolerance if ``absolute``)."""
        limit = np.broadcast_to(np.asarray(limit, float), (self.model.nq,))
        bound = limit + (self.tolerance if absolute else self.tolerance * limit)
        over = (value - bound).reshape(-1, self.model.nq)
        when = np.broadcast_to(when, value.shape).reshape(-1, self.model.nq)
        value = value.reshape(-1, self.model.nq)
        out = []
        for j in np.flatnonzero((over > 0).any(axis=0)):
            i = int(np.argmax(over[:, j]))
            out.append(Violation(kind, self.model.joint_names[j], float(when[i, j]), float(value[i, j]),
                                 float(limit[j]), unit))
        return out

    def _positions(self, t, q) -> list[Violation]:
        lo, hi = self.limits.lower_rad, self.limits.upper_rad
        return (self._exceed("position", q - hi, t[:, None], 0.0, "rad above the upper limit", absolute=True)
                + self._exceed("position", lo - q, t[:, None], 0.0, "rad below the lower limit", absolute=True))

    def _workspace(self, ts, qs) -> list[Violation]:
        tips = np.array([self.model.fk(q)[0] for q in np.atleast_2d(qs)])
        outside = ~self.box.inside(tips, self.box_slack_m)
        if not outside.any():
            return []
        i = int(np.flatnonzero(outside)[0])
        below = np.maximum(self.box.lower_xyz - tips[i], 0.0)
        above = np.maximum(tips[i] - self.box.upper_xyz, 0.0)
        dist = float(np.max(np.r_[below, above]))
        return [Violation("workspace", "", float(np.atleast_1d(ts)[i]), dist, 0.0,
                          f"m outside the box: tip {np.round(tips[i], 4).tolist()} "
                          f"({int(outside.sum())} of {len(tips)} samples)")]


def _bad(why: str) -> Violation:
    return Violation("malformed", "", 0.0, float("nan"), float("nan"), why)
