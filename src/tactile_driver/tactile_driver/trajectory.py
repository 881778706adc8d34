"""Time-parameterised joint trajectories along a Cartesian fingertip path.

1. ``densify``: the tip polyline (world frame) is resampled so that no step
   exceeds ``max_step_m``. With finger axes (``densify_with_axes``) each
   point carries a target axis of the fingertip z-axis; on a segment the axis
   turns along the great circle from one point's axis to the next (slerp, by
   the fraction of the segment), and no step turns it more than
   ``max_step_rad`` either: a point repeated with another axis is a rotation
   of the finger in place, about the tip centre.
2. ``ik_path``: IK per waypoint, each warm-started from the previous one
   (continuity); a joint jump above ``max_joint_step_rad`` between neighbours
   is rejected (a flip of the elbow is not a path). With axes, a waypoint is
   first solved to the tighter tracking tolerance ``AXIS_TRACK_FRACTION ·
   max_step_rad`` on the axis (else the IK, content within ``max_tilt_rad``,
   would leave the finger where it is for a step or two and then catch up in
   one doubled step), falling back to ``max_tilt_rad`` where that fails.
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

Rest to rest: the first and last waypoint velocities are zero. A segment
without tip travel (a rotation in place) gets the floored length
``MIN_SEGMENT_M`` as its path length: its tangent is then large and the joint
velocity and acceleration limits set its time (the tip speed bounds nothing
there), with no division by zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from tactile_common.finger_axis import SAME_AXIS_RAD, axis_angles, slerp_axes
from tactile_driver.ik import MIN_AXIS_NORM, IKSettings, NoSolutionFound, solve_ik
from tactile_driver.kinematics import ArmModel


_LOCAL_ITERATIONS = 8
#: Tip points closer than this are merged (IK residuals must not create micro-segments).
MERGE_TOL_M = 2e-4
#: ... unless their finger axes differ by more than this (rad): then the second is a rotation in place.
MERGE_TOL_RAD = SAME_AXIS_RAD
#: Default largest turn of the finger axis between two waypoints (rad), when axes are given. Near vertical
#: a 0.1 rad turn took up to 0.33 rad of joint 5 (above the default max_joint_step_rad, 0.3); 0.05 rad halves it.
MAX_AXIS_STEP_RAD = 0.05
#: With axes, waypoints are solved to this fraction of the angular step first (tracking tolerance).
AXIS_TRACK_FRACTION = 0.25
#: Path length given to a segment without tip travel (m): time_parameterize's floor.
MIN_SEGMENT_M = 1e-6


class TrajectoryError(ValueError):
    """A path that cannot become a trajectory (IK failure, discontinuity, bad input)."""


class PathNotFeasible(TrajectoryError):
    """IK failed at a waypoint.

    Attributes:
        index: waypoint index in the densified path.
        point_xyz: that waypoint (world, m).
        cause: the :class:`NoSolutionFound` raised by IK.
    """

    def __init__(self, index: int, point_xyz: np.ndarray, cause: NoSolutionFound,
                 axis_xyz: Optional[np.ndarray] = None) -> None:
        self.index = int(index)
        self.point_xyz = np.asarray(point_xyz, dtype=float)
        self.axis_xyz = None if axis_xyz is None else np.asarray(axis_xyz, dtype=float)
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
        meta: ``n_joints``; ``axes_xyz`` (K, 3), the target finger axes of the waypoints (world,
            unit), when the plan was made with axes.
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


def unit_axes(axes_xyz: np.ndarray, n_points: int) -> np.ndarray:
    """``axes_xyz`` as (n_points, 3) unit vectors (world), one per path point.

    Raises:
        TrajectoryError: wrong shape, NaN or inf, or an axis of norm below ``MIN_AXIS_NORM``.
    """
    try:
        a = np.asarray(axes_xyz, dtype=float)
    except (TypeError, ValueError):
        raise TrajectoryError("finger axes must be numbers") from None
    if a.ndim == 1 and a.size == 3 and n_points == 1:
        a = a[None]
    if a.shape != (n_points, 3):
        raise TrajectoryError(f"finger axes must be a ({n_points}, 3) array, one per path point, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise TrajectoryError("finger axes contain NaN or inf")
    norm = np.linalg.norm(a, axis=1)
    if np.any(norm < MIN_AXIS_NORM):
        raise TrajectoryError(f"finger axis {int(np.argmax(norm < MIN_AXIS_NORM))} is zero: it has no direction")
    return a / norm[:, None]


def densify_with_axes(path_xyz: np.ndarray, axes_xyz: np.ndarray, max_step_m: float,
                      max_step_rad: float = MAX_AXIS_STEP_RAD) -> tuple[np.ndarray, np.ndarray]:
    """Resample a polyline (K, 3) with a finger axis per point (K, 3) (world; normalised here).

    Per segment k (points p_k → p_{k+1}, axes a_k → a_{k+1}, angle θ_k between them):
    n_k = max(1, ⌈|Δp_k| / max_step_m⌉, ⌈θ_k / max_step_rad⌉) equal steps; the point at
    fraction f = i / n_k is p_k + f Δp_k, its axis slerp(a_k, a_{k+1}, f), so no step moves the
    tip more than ``max_step_m`` nor turns the axis more than ``max_step_rad``. A point is
    dropped only when it repeats the previous one in position (≤ ``MERGE_TOL_M``) and axis
    (≤ ``MERGE_TOL_RAD``): a point repeated with another axis is a rotation in place.

    Returns:
        (points (M, 3), axes (M, 3)); the last ones are the last path point and axis exactly.

    Raises:
        TrajectoryError: bad shapes, NaN or inf, a zero axis, a non-positive step.
    """
    p = np.asarray(path_xyz, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise TrajectoryError(f"path must be a non-empty (K, 3) array, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise TrajectoryError("path contains NaN or inf")
    if max_step_m <= 0 or not max_step_rad > 0:
        raise TrajectoryError("max_step_m and max_step_rad must be positive")
    a = unit_axes(axes_xyz, len(p))
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    ang = axis_angles(a[:-1], a[1:])
    keep = np.concatenate([[True], (seg > MERGE_TOL_M) | (ang > MERGE_TOL_RAD)])
    last = np.flatnonzero(keep)[-1]
    if last > 0 and not keep[-1]:  # end exactly at the last point (and axis), not at its near-duplicate
        keep[last], keep[-1] = False, True
    p, a = p[keep], a[keep]
    if len(p) == 1:
        return p, a
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    ang = axis_angles(a[:-1], a[1:])
    n_sub = np.maximum.reduce([np.ones(len(seg), dtype=int),
                               np.ceil(seg / max_step_m - 1e-9).astype(int),
                               np.ceil(ang / max_step_rad - 1e-9).astype(int)])
    seg_idx = np.repeat(np.arange(len(seg)), n_sub)
    frac = np.concatenate([np.arange(n) / n for n in n_sub])
    out_p = p[seg_idx] + frac[:, None] * (p[seg_idx + 1] - p[seg_idx])
    out_a = slerp_axes(a[seg_idx], a[seg_idx + 1], frac)
    return np.vstack([out_p, p[-1:]]), np.vstack([out_a, a[-1:]])


def ik_path(
    model: ArmModel,
    path_xyz: np.ndarray,
    q_start: np.ndarray,
    settings: IKSettings = IKSettings(),
    max_joint_step_rad: float = 0.3,
    axes_xyz: Optional[np.ndarray] = None,
    track_tilt_rad: Optional[float] = None,
) -> np.ndarray:
    """(K, n) joint positions for the tip waypoints, each warm-started from the previous one.

    ``axes_xyz`` (K, 3): the target fingertip z-axis of each waypoint (world; normalised
    here); None: vertical everywhere (the IK's default, unchanged). ``track_tilt_rad`` (with
    axes): each waypoint is first solved to an axis error ≤ min(``max_tilt_rad``,
    ``track_tilt_rad``), and only where that fails to ``max_tilt_rad``.

    Raises:
        PathNotFeasible: IK fails at a waypoint.
        Discontinuity: neighbouring solutions differ by more than ``max_joint_step_rad``.
        TrajectoryError: axes of the wrong shape, not finite, or zero.
    """
    path = np.asarray(path_xyz, dtype=float)
    axes = None if axes_xyz is None else unit_axes(axes_xyz, len(path))
    qs = np.empty((len(path), model.nq))
    q = np.asarray(q_start, dtype=float)
    for k, target in enumerate(path):
        try:
            if axes is None:
                q = solve_ik(model, target, q, settings).q
            else:
                q = _solve_tracking(model, target, q, settings, axes[k], track_tilt_rad)
        except NoSolutionFound as exc:
            raise PathNotFeasible(k, target, exc, None if axes is None else axes[k]) from None
        qs[k] = q
    jumps = np.abs(np.diff(np.vstack([np.asarray(q_start, float)[None], qs]), axis=0))
    # The first waypoint is allowed to move the start posture (it may be off the start point).
    jumps[0] = 0.0
    bad = np.argwhere(jumps > max_joint_step_rad)
    if len(bad):
        k, j = bad[0]
        raise Discontinuity(int(k), model.joint_names[j], jumps[k, j], max_joint_step_rad)
    return qs


def _solve_tracking(model: ArmModel, target_xyz: np.ndarray, q_init: np.ndarray, settings: IKSettings,
                    axis_xyz: np.ndarray, track_tilt_rad: Optional[float]) -> np.ndarray:
    """IK of one waypoint with an axis: to ``track_tilt_rad`` on the axis if that converges, else to
    ``settings.max_tilt_rad`` (the failure of that one is raised)."""
    if track_tilt_rad is not None and track_tilt_rad < settings.max_tilt_rad:
        try:
            return solve_ik(model, target_xyz, q_init, replace(settings, max_tilt_rad=track_tilt_rad),
                            axis_xyz=axis_xyz).q
        except NoSolutionFound:
            pass
    return solve_ik(model, target_xyz, q_init, settings, axis_xyz=axis_xyz).q


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


def time_parameterize(qs: np.ndarray, tip_xyz: np.ndarray, limits: MotionLimits,
                      axes_xyz: Optional[np.ndarray] = None, lever_m: float = 0.0) -> TimedTrajectory:
    """Times and velocities for joint waypoints along a tip path, rest to rest (see module doc).

    With the waypoints' finger axes (``axes_xyz`` (K, 3), unit) the path parameter of a segment is the
    larger of the tip's travel and the arc ``lever_m`` · Δangle a point that far along the finger moves
    through (the flange, for ``lever_m`` = the tip offset): a turn in place then has a length, the tip
    speed limits that point's speed, and its waypoints' corner limits do not collapse to the floor's
    (a 45° turn took 6.5 s at 1 rad/s joint limits, now ~2 s). Without axes, as before."""
    qs = np.asarray(qs, dtype=float)
    tip = np.asarray(tip_xyz, dtype=float)
    n = qs.shape[1]
    if len(qs) < 2:
        return TimedTrajectory(np.zeros(1), qs.copy(), np.zeros_like(qs), tip.copy())
    ds_tip = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    if axes_xyz is not None and lever_m > 0:
        a = np.asarray(axes_xyz, dtype=float)
        ds_tip = np.maximum(ds_tip, lever_m * axis_angles(a[:-1], a[1:]))
    dq = np.diff(qs, axis=0)
    # Path parameter: tip arc length, floored so a pure reorientation still has a length.
    ds = np.maximum(ds_tip, MIN_SEGMENT_M)
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
    axes_xyz: Optional[np.ndarray] = None,
    max_step_rad: float = MAX_AXIS_STEP_RAD,
) -> TimedTrajectory:
    """Rest-to-rest trajectory from ``q_start`` through the tip polyline ``path_xyz`` (world, m).

    The current tip position (FK of ``q_start``) is prepended to the path, so
    the trajectory starts exactly at the measured state.

    ``axes_xyz`` (K, 3): the target fingertip z-axis (tip → flange, world) at each path point.
    The start's axis is the fingertip z-axis of ``q_start`` (FK); densification turns it along
    great circles, at most ``max_step_rad`` per waypoint (:func:`densify_with_axes`), each
    waypoint is tracked to ``AXIS_TRACK_FRACTION · max_step_rad`` where the IK gets there
    (:func:`ik_path`; the end then lies that close to the last axis, else within
    ``max_tilt_rad``), and the waypoint axes are kept in ``meta['axes_xyz']``. None: the
    vertical finger, planned exactly as without axes (``max_step_rad`` unused).
    """
    if axes_xyz is None:
        return _plan_vertical(model, path_xyz, q_start, limits, max_step_m, settings, max_joint_step_rad)
    return _plan_with_axes(model, path_xyz, q_start, limits, max_step_m, settings, max_joint_step_rad, axes_xyz,
                           max_step_rad)


def _plan_vertical(model: ArmModel, path_xyz: np.ndarray, q_start: np.ndarray, limits: MotionLimits,
                   max_step_m: float, settings: IKSettings, max_joint_step_rad: float) -> TimedTrajectory:
    """:func:`plan_tip_path` without axes: the finger vertical (the plan as it was before axes)."""
    start_xyz, _ = model.fk(q_start)
    path = densify(np.vstack([start_xyz[None], np.asarray(path_xyz, dtype=float).reshape(-1, 3)]), max_step_m)
    qs = ik_path(model, path[1:], q_start, settings, max_joint_step_rad) if len(path) > 1 else np.empty((0, model.nq))
    qs = np.vstack([np.asarray(q_start, float)[None], qs])
    return time_parameterize(qs, path, limits)


def _plan_with_axes(model: ArmModel, path_xyz: np.ndarray, q_start: np.ndarray, limits: MotionLimits,
                    max_step_m: float, settings: IKSettings, max_joint_step_rad: float, axes_xyz: np.ndarray,
                    max_step_rad: float) -> TimedTrajectory:
    """:func:`plan_tip_path` with a finger axis per path point (world), from the start's FK axis."""
    start_xyz, start_rot = model.fk(q_start)
    points = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
    axes = unit_axes(axes_xyz, len(points))
    path, path_axes = densify_with_axes(np.vstack([start_xyz[None], points]), np.vstack([start_rot[None, :, 2], axes]),
                                        max_step_m, max_step_rad)
    qs = (ik_path(model, path[1:], q_start, settings, max_joint_step_rad, path_axes[1:],
                  AXIS_TRACK_FRACTION * max_step_rad) if len(path) > 1 else np.empty((0, model.nq)))
    traj = time_parameterize(np.vstack([np.asarray(q_start, float)[None], qs]), path, limits, path_axes,
                             model.tip_offset_m)
    traj.meta["axes_xyz"] = path_axes
    return traj


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
