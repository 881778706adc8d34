"""Time-parameterised joint trajectories along a Cartesian fingertip path.

1. ``densify``: the tip polyline (world frame) is resampled so that no step
   exceeds ``max_step_m``.
2. ``ik_path``: IK per waypoint, each warm-started from the previous one
   (continuity); a joint jump above ``max_joint_step_rad`` between neighbours
   is rejected (a flip of the elbow is not a path).
3. ``time_parameterize`` (TOPP-lite): with s the tip arc length and q'(s) the
   joint tangent of each segment, the path speed is limited per segment by
   ṡ ≤ min(v_tip, min_j v_j / |q'_j|), its acceleration by
   s̈ ≤ min_j a_j / |q'_j|, and at each corner by the tangent change
   ṡ² |Δq'_j| / Δs ≤ a_j. A forward and a backward pass (ṡ_{k+1}² ≤ ṡ_k² +
   2 s̈ Δs) give the waypoint speeds, trapezoids the segment durations.
   The trajectory is sent as (t_k, q_k, q̇_k) and executed as a cubic Hermite
   spline (what ros2_control's joint_trajectory_controller does when
   positions and velocities are given). The exact extrema of that spline's
   velocity (a quadratic per segment) and acceleration (linear) are then
   checked, and time is stretched uniformly, t → c t, q̇ → q̇ / c, so that
   every joint velocity and acceleration limit holds exactly.

Rest to rest: the first and last waypoint velocities are zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from tactile_driver.ik import IKSettings, NoSolutionFound, solve_ik
from tactile_driver.kinematics import ArmModel


_LOCAL_ITERATIONS = 8
#: Tip points closer than this are merged (IK residuals must not create micro-segments).
MERGE_TOL_M = 2e-4


class TrajectoryError(ValueError):
    """A path that cannot become a trajectory (IK failure, discontinuity, bad input)."""


class PathNotFeasible(TrajectoryError):
    """IK failed at a waypoint.

    Attributes:
        index: waypoint index in the densified path.
        point_xyz: that waypoint (world, m).
        cause: the :class:`NoSolutionFound` raised by IK.
    """

    def __init__(self, index: int, point_xyz: np.ndarray, cause: NoSolutionFound) -> None:
        self.index = int(index)
        self.point_xyz = np.asarray(point_xyz, dtype=float)
        self.cause = cause
        super().__init__(f"waypoint {index} unreachable: {cause}")


class Discontinuity(TrajectoryError):
    """Two neighbouring waypoints need a joint jump larger than allowed."""

    def __init__(self, index: int, joint: str, jump_rad: float, max_rad: float) -> None:
        self.index, self.joint, self.jump_rad, self.max_rad = int(index), joint, float(jump_rad), float(max_rad)
        super().__init__(
            f"joint '{joint}' jumps {jump_rad:.3f} rad between waypoints {index - 1} and {index} "
            f"(max {max_rad:.3f} rad): the IK branch changed"
        )


@dataclass(frozen=True)
class MotionLimits:
    """Joint and tip limits (arrays in joint order; rad, rad/s, rad/s², m/s)."""

    lower_rad: np.ndarray
    upper_rad: np.ndarray
    velocity_rad_s: np.ndarray
    acceleration_rad_s2: np.ndarray
    tip_speed_mps: float = 0.10

    @classmethod
    def for_model(cls, model: ArmModel, velocity_rad_s, acceleration_rad_s2, tip_speed_mps: float) -> "MotionLimits":
        """Limits from the URDF (position, velocity) and the given caps (the tighter one wins)."""
        v = np.minimum(np.broadcast_to(np.asarray(velocity_rad_s, float), (model.nq,)), model.velocity_limit_rad_s)
        a = np.broadcast_to(np.asarray(acceleration_rad_s2, float), (model.nq,)).copy()
        if np.any(v <= 0) or np.any(a <= 0) or tip_speed_mps <= 0:
            raise TrajectoryError("velocity, acceleration and tip speed limits must be positive")
        return cls(model.lower_rad.copy(), model.upper_rad.copy(), v, a, float(tip_speed_mps))


@dataclass
class TimedTrajectory:
    """Joint waypoints with times; executed as a cubic Hermite spline.

    Attributes:
        times_s: (K,) time from start of each waypoint, increasing, first 0.
        positions_rad: (K, n) joint positions.
        velocities_rad_s: (K, n) joint velocities (zero at both ends).
        tip_xyz: (K, 3) the tip waypoints (world, m) the positions were solved for.
    """

    times_s: np.ndarray
    positions_rad: np.ndarray
    velocities_rad_s: np.ndarray
    tip_xyz: np.ndarray
    time_scale: float = 1.0
    meta: dict = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.tip_xyz, axis=0), axis=1).sum())


def densify(path_xyz: np.ndarray, max_step_m: float) -> np.ndarray:
    """Resample a polyline (K, 3) so that no step exceeds ``max_step_m``; repeated points dropped."""
    p = np.asarray(path_xyz, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise TrajectoryError(f"path must be a non-empty (K, 3) array, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise TrajectoryError("path contains NaN or inf")
    if max_step_m <= 0:
        raise TrajectoryError("max_step_m must be positive")
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    keep = np.concatenate([[True], seg > MERGE_TOL_M])
    last = np.flatnonzero(keep)[-1]
    if last > 0 and not keep[-1]:  # end exactly at the last point, not at its near-duplicate
        keep[last], keep[-1] = False, True
    p = p[keep]
    if len(p) == 1:
        return p
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    # A length that is a whole number of steps (an approach of 4 cm in 5 mm steps) must not become one
    # more step when it is 1e-14 m longer: that would give another trajectory for the same motion.
    n_sub = np.maximum(1, np.ceil(seg / max_step_m - 1e-9).astype(int))
    # For segment k, fractions 0, 1/n, ..., (n-1)/n; then the last point.
    seg_idx = np.repeat(np.arange(len(seg)), n_sub)
    frac = np.concatenate([np.arange(n) / n for n in n_sub])
    out = p[seg_idx] + frac[:, None] * (p[seg_idx + 1] - p[seg_idx])
    return np.vstack([out, p[-1:]])


def ik_path(
    model: ArmModel,
    path_xyz: np.ndarray,
    q_start: np.ndarray,
    settings: IKSettings = IKSettings(),
    max_joint_step_rad: float = 0.3,
) -> np.ndarray:
    """(K, n) joint positions for the tip waypoints, each warm-started from the previous one.

    Raises:
        PathNotFeasible: IK fails at a waypoint.
        Discontinuity: neighbouring solutions differ by more than ``max_joint_step_rad``.
    """
    path = np.asarray(path_xyz, dtype=float)
    qs = np.empty((len(path), model.nq))
    q = np.asarray(q_start, dtype=float)
    for k, target in enumerate(path):
        try:
            q = solve_ik(model, target, q, settings).q
        except NoSolutionFound as exc:
            raise PathNotFeasible(k, target, exc) from None
        qs[k] = q
    jumps = np.abs(np.diff(np.vstack([np.asarray(q_start, float)[None], qs]), axis=0))
    # The first waypoint is allowed to move the start posture (it may be off the start point).
    jumps[0] = 0.0
    bad = np.argwhere(jumps > max_joint_step_rad)
    if len(bad):
        k, j = bad[0]
        raise Discontinuity(int(k), model.joint_names[j], jumps[k, j], max_joint_step_rad)
    return qs


def _trapezoid_time(v0: np.ndarray, v1: np.ndarray, vmax: np.ndarray, a: np.ndarray, ds: np.ndarray) -> np.ndarray:
    """Time to cover ds starting at speed v0 and ending at v1, speed ≤ vmax, |accel| ≤ a (vectorised)."""
    v_peak = np.sqrt(np.maximum((v0**2 + v1**2) / 2.0 + a * ds, 0.0))
    tri = v_peak <= vmax
    t_tri = (2.0 * v_peak - v0 - v1) / a
    d_acc = (vmax**2 - v0**2) / (2.0 * a)
    d_dec = (vmax**2 - v1**2) / (2.0 * a)
    t_trap = (vmax - v0) / a + (vmax - v1) / a + np.maximum(ds - d_acc - d_dec, 0.0) / vmax
    return np.where(tri, t_tri, t_trap)


def hermite_extrema(times_s: np.ndarray, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per segment and joint (K-1, n): max |velocity| and max |acceleration| of the cubic Hermite spline (exact).

    Per segment of length h with p = q1 - q0: acceleration is linear, with
    end values (6p - h(4v0 + 2v1))/h² and (-6p + h(2v0 + 4v1))/h²; velocity
    is quadratic, its extremum (if inside) where the acceleration is zero.
    """
    h = np.diff(times_s)[:, None]
    p = np.diff(q, axis=0)
    v0, v1 = qd[:-1], qd[1:]
    a0 = (6.0 * p - h * (4.0 * v0 + 2.0 * v1)) / h**2
    a1 = (-6.0 * p + h * (2.0 * v0 + 4.0 * v1)) / h**2
    acc = np.maximum(np.abs(a0), np.abs(a1))
    # v(τ) = v0 + a0 τ + (a1 - a0) τ² / (2h); extremum at τ* = -a0 h / (a1 - a0).
    da = a1 - a0
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(np.abs(da) > 1e-12, -a0 * h / da, -1.0)
    inside = (tau > 0) & (tau < h)
    v_star = np.where(inside, v0 + a0 * tau + da * tau**2 / (2.0 * h), 0.0)
    vel = np.maximum(np.maximum(np.abs(v0), np.abs(v1)), np.abs(v_star))
    return vel, acc


def time_parameterize(qs: np.ndarray, tip_xyz: np.ndarray, limits: MotionLimits) -> TimedTrajectory:
    """Times and velocities for joint waypoints along a tip path, rest to rest (see module doc)."""
    qs = np.asarray(qs, dtype=float)
    tip = np.asarray(tip_xyz, dtype=float)
    n = qs.shape[1]
    if len(qs) < 2:
        return TimedTrajectory(np.zeros(1), qs.copy(), np.zeros_like(qs), tip.copy())
    ds_tip = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    dq = np.diff(qs, axis=0)
    # Path parameter: tip arc length, floored so a pure reorientation still has a length.
    ds = np.maximum(ds_tip, 1e-6)
    tangent = dq / ds[:, None]  # q'(s) per segment
    abs_t = np.maximum(np.abs(tangent), 1e-12)
    v_seg = np.minimum(limits.tip_speed_mps, (limits.velocity_rad_s / abs_t).min(axis=1))
    a_seg = (limits.acceleration_rad_s2 / abs_t).min(axis=1)
    # Waypoint speed limits: rest at both ends, adjacent segments and corners inside.
    w = np.zeros(len(qs))
    if len(qs) > 2:
        dtan = np.maximum(np.abs(np.diff(tangent, axis=0)), 1e-12)
        ds_min = np.minimum(ds[:-1], ds[1:])[:, None]
        corner = np.sqrt(limits.acceleration_rad_s2 * ds_min / dtan).min(axis=1)
        w[1:-1] = np.minimum(np.minimum(v_seg[:-1], v_seg[1:]), corner)
    # Waypoint joint velocity: path speed times the mean of the adjacent tangents.
    tan_wp = np.zeros_like(qs)
    tan_wp[1:-1] = 0.5 * (tangent[:-1] + tangent[1:])
    for _ in range(_LOCAL_ITERATIONS):
        _forward_backward(w, a_seg, ds)
        dt = _trapezoid_time(w[:-1], w[1:], v_seg, a_seg, ds)
        times = np.concatenate([[0.0], np.cumsum(dt)])
        qd = w[:, None] * tan_wp
        vel, acc = hermite_extrema(times, qs, qd)
        ratio = np.maximum(vel / limits.velocity_rad_s, np.sqrt(acc / limits.acceleration_rad_s2)).max(axis=1)
        if ratio.max() <= 1.0:
            break
        # Slow down locally: the speeds at both ends of a violating segment, and its cruise speed.
        over = np.maximum(ratio, 1.0)
        w[:-1] /= over
        w[1:] /= over
        v_seg = v_seg / over
    c = max(1.0, float(ratio.max())) * (1.0 + 1e-9)  # uniform stretch: exact for the spline
    return TimedTrajectory(times * c, qs.copy(), qd / c, tip.copy(), time_scale=c, meta={"n_joints": n})


def _forward_backward(w: np.ndarray, a_seg: np.ndarray, ds: np.ndarray) -> None:
    """In place: w_{k+1}² ≤ w_k² + 2 a_k ds_k forwards, then the same backwards."""
    for k in range(len(ds)):
        w[k + 1] = min(w[k + 1], np.sqrt(w[k] ** 2 + 2.0 * a_seg[k] * ds[k]))
    for k in range(len(ds) - 1, -1, -1):
        w[k] = min(w[k], np.sqrt(w[k + 1] ** 2 + 2.0 * a_seg[k] * ds[k]))


def plan_tip_path(
    model: ArmModel,
    path_xyz: np.ndarray,
    q_start: np.ndarray,
    limits: MotionLimits,
    max_step_m: float = 0.01,
    settings: IKSettings = IKSettings(),
    max_joint_step_rad: float = 0.3,
) -> TimedTrajectory:
    """Rest-to-rest trajectory from ``q_start`` through the tip polyline ``path_xyz`` (world, m).

    The current tip position (FK of ``q_start``) is prepended to the path, so
    the trajectory starts exactly at the measured state.
    """
    start_xyz, _ = model.fk(q_start)
    path = densify(np.vstack([start_xyz[None], np.asarray(path_xyz, dtype=float).reshape(-1, 3)]), max_step_m)
    qs = ik_path(model, path[1:], q_start, settings, max_joint_step_rad) if len(path) > 1 else np.empty((0, model.nq))
    qs = np.vstack([np.asarray(q_start, float)[None], qs])
    return time_parameterize(qs, path, limits)


def sample_hermite(traj: TimedTrajectory, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of the executed spline at times ``t_s`` (held outside)."""
    t = np.clip(np.asarray(t_s, dtype=float), traj.times_s[0], traj.times_s[-1])
    k = np.clip(np.searchsorted(traj.times_s, t, side="right") - 1, 0, len(traj.times_s) - 2)
    if len(traj.times_s) < 2:
        return np.repeat(traj.positions_rad[:1], len(t), 0), np.zeros((len(t), traj.positions_rad.shape[1]))
    h = (traj.times_s[k + 1] - traj.times_s[k])[:, None]
    s = (t - traj.times_s[k])[:, None] / h
    q0, q1 = traj.positions_rad[k], traj.positions_rad[k + 1]
    v0, v1 = traj.velocities_rad_s[k] * h, traj.velocities_rad_s[k + 1] * h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    q = h00 * q0 + h10 * v0 + h01 * q1 + h11 * v1
    qd = (d00 * q0 + d10 * v0 + d01 * q1 + d11 * v1) / h
    return q, qd
