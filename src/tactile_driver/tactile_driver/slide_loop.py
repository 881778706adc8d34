"""A slide on the node graph, one control tick at a time (ROS-free).

World frame, metres, seconds of the node clock (simulated time on the rig).
The arm commander runs the servo of :mod:`tactile_driver.slide_servo` as a
closed loop over topics:

- the driver streams the per-frame contact while the finger is in contact
  (``/tactile/contact_frames``: one point per frame, then an empty cloud at
  the frame the contact is released); :meth:`SlideLoop.on_frame` takes each;
- every ``1 / control_rate_hz`` (:meth:`SlideLoop.due`, the node's timer) it
  calls :meth:`SlideLoop.tick` with the forward-kinematics tip of the latest
  joint state and the latest frame's contact (none after a release), once a
  frame stamped at or after the previous tick's command has come in: the
  servo never acts twice on what it sensed before its last action (a sensing
  pipeline that lags makes the loop slower, never unstable). Without such a
  frame for ``max_contact_age_s`` (a silent driver) the tick goes ahead
  without contact, so the slide ends on the servo's lost rule;
- the tick's target becomes a short replacing trajectory (:func:`tick_trajectory`);
  ros2_control's joint_trajectory_controller interpolates to it from its
  current state (position and velocity) and a new one replaces it at the
  next tick:

  - streamed (:func:`servo_stream_trajectory`, while the servo steps along
    the surface): the target where the tip will be at the slide speed one
    tick interval on, reached moving at that speed, then a stopping tail to
    rest; the arm runs at the slide speed, each segment within the limits
    from the measured state; the direction is turned by the surface's curvature (estimated from the sensed tangent's turn per metre,
    :attr:`SlideLoop.curvature_per_m`) over the tick's lag;
  - rest-ended (:func:`servo_step_trajectory`: while the contact is
    regained, or with ``stream`` off): one point, the IK of the target at
    rest, ``T`` seconds from the start, ``T`` the shortest duration (≥ one
    tick) whose cubic Hermite segment keeps every joint within its velocity
    and acceleration limits and the tip within ``tip_speed_mps``, both from
    rest and from the measured joint velocity, so each trajectory is within
    the :class:`~tactile_driver.trajectory.MotionLimits` whatever the state
    it replaces;

  the target is checked against the workspace box first. When the servo
  stops, :func:`stopping_trajectory` brings the moving arm to rest.

The slid length is the arm's: each tick adds the measured tip's advance
along the tangent of the previous step, (p_k − p_{k−1})·t_{k−1}, and the
servo's slid length is set to it each tick (its length and lap rules go by
it), so a slide ends after the planned length *travelled* (an arm that lags its targets slides
as far as planned, only slower). With an arm that reaches each target within
the tick this is the servo's own sum of steps (the offline slide).

The thinned stream (:class:`~tactile_driver.slide_servo.ContactThinner`,
offered every frame with force ≥ ``min_force_n``, as offline) is what the
commander publishes on ``/tactile/contacts``; :meth:`SlideLoop.finish`
closes it with the last good contact (the end of the sensed arc), as
:func:`tactile_sim.slide.simulate_slide` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from tactile_driver.ik import IKSettings, solve_ik
from tactile_driver.kinematics import ArmModel
from tactile_driver.safety import OutsideWorkspace, WorkspaceBox
from tactile_driver.slide_servo import (ContactSense, ContactThinner, SlideServo, SlideServoConfig, SlideStep, _unit,
                                       SlideStop)
from tactile_driver.trajectory import MotionLimits, TimedTrajectory, TrajectoryError, hermite_extrema


@dataclass(frozen=True)
class FrameContact:
    """One frame of the driver's stream: its stamp (s) and the contact (None: released)."""

    stamp_s: float
    sense: Optional[ContactSense]


class SlideLoop:
    """The servo, its thinning and its tick schedule for one slide (module docstring)."""

    def __init__(self, config: SlideServoConfig, direction_xyz: np.ndarray, length_m: float,
                 box_min_xyz: np.ndarray, box_max_xyz: np.ndarray, start_s: float, planar: bool = False,
                 max_contact_age_s: float = 0.25, normal_xyz: Optional[np.ndarray] = None) -> None:
        if not max_contact_age_s > 0:
            raise ValueError(f"max_contact_age_s = {max_contact_age_s}: must be > 0")
        cfg = config.validate()
        # The tick limit guards against no progress: an arm that lags its targets needs more ticks.
        max_ticks = int(np.ceil(6.0 * 3.0 * length_m / cfg.step_m)) + 10 * cfg.lost_ticks
        self.servo = SlideServo(cfg, direction_xyz, length_m, box_min_xyz, box_max_xyz, planar=planar,
                                max_ticks=max_ticks, normal_xyz=normal_xyz)
        self.config = cfg
        self.length_m = float(length_m)
        self.progress_m = 0.0  # the measured advance along the slide (module docstring)
        self._last_tip: Optional[np.ndarray] = None
        self._last_tangent: Optional[np.ndarray] = None
        self.thinner = ContactThinner(self.config.thin_distance_m, self.config.thin_angle_rad)
        self.period_s = 1.0 / self.config.control_rate_hz
        self.start_s = float(start_s)
        self.max_contact_age_s = float(max_contact_age_s)
        self.next_tick_s = self.start_s
        self.latest: Optional[FrameContact] = None
        self.last_good: Optional[FrameContact] = None  # the newest frame with force ≥ min_force_n
        self.published: list[FrameContact] = []  # the thinned stream, in the order sensed
        self._outbox: list[FrameContact] = []
        self.tip_path: list[np.ndarray] = []
        self.stop = None
        self.frames = 0
        self.last_command_s = self.start_s  # when the latest target was sent (the arm was at rest at the start)
        self._last_tick_s: Optional[float] = None
        self.interval_s = self.period_s  # smoothed time between ticks (fresh frames pace them)
        self.curvature_per_m = 0.0  # smoothed turn of the sensed tangent per metre slid (1/m)

    # -- inputs -------------------------------------------------------------------
    def on_frame(self, frame: FrameContact) -> None:
        """A frame of the driver's stream; frames from before the slide began are ignored."""
        if frame.stamp_s < self.start_s - 1e-9 or self.stop is not None:
            return
        if self.latest is not None and frame.stamp_s < self.latest.stamp_s:
            return  # out of order: the newer one stands
        self.latest = frame
        self.frames += 1
        s = frame.sense
        if s is None or not (s.force_n >= self.config.min_force_n) or not np.all(np.isfinite(s.point_xyz)):
            return
        self.last_good = frame
        if self.thinner.offer(s):
            self._emit(frame)

    def fresh(self) -> bool:
        """The latest frame was sensed at or after the latest command (module docstring)."""
        return self.latest is not None and self.latest.stamp_s >= self.last_command_s - 1e-9

    def current(self, now_s: float) -> Optional[ContactSense]:
        """The contact the servo sees now: the latest frame's if it is fresh (module docstring)."""
        return self.latest.sense if self.fresh() else None

    # -- the loop -----------------------------------------------------------------
    def due(self, now_s: float) -> bool:
        """A tick is due: its time has come and a fresh frame is in (or none came for
        ``max_contact_age_s`` since the latest command)."""
        if self.stop is not None or now_s < self.next_tick_s - 1e-9:
            return False
        return self.fresh() or now_s - self.last_command_s >= self.max_contact_age_s

    def tick(self, now_s: float, tip_xyz: np.ndarray) -> SlideStep:
        """One control tick; the next tick is one period later (missed ticks are skipped, not caught up)."""
        self.next_tick_s = max(self.next_tick_s + self.period_s, now_s + 0.5 * self.period_s)
        if self._last_tick_s is not None:
            self.interval_s += 0.3 * (float(now_s) - self._last_tick_s - self.interval_s)
        self._last_tick_s = float(now_s)
        tip = np.asarray(tip_xyz, dtype=float).reshape(3)
        self.tip_path.append(tip.copy())
        advance_m = 0.0
        if self._last_tip is not None:
            advance_m = float((tip - self._last_tip) @ self._last_tangent)
            self.progress_m += advance_m
        # the servo's slid length is the measured one (module docstring): its length and lap rules,
        # and its last step, go by where the arm is, not by the steps it was sent
        self.servo.slid_m = self.progress_m
        step = self.servo.step(tip, self.current(now_s))
        if step.target_xyz is not None:
            self.last_command_s = float(now_s)
        if self._last_tangent is not None and self.servo.normal is not None and advance_m > 1e-4:
            # the tangent turns towards −n by κ per metre slid: t ← t − κ Δs n (κ > 0 on a convex surface)
            sample = float((self._last_tangent - self.servo.tangent) @ self.servo.normal) / advance_m
            self.curvature_per_m += 0.3 * (float(np.clip(sample, -200.0, 200.0)) - self.curvature_per_m)
        self._last_tip, self._last_tangent = tip, self.servo.tangent.copy()  # this step's advance: next tick
        if step.stop is not None:
            self.stop = step.stop
        return step

    @property
    def horizon_s(self) -> float:
        """How far ahead a velocity-continuous step aims (s): the smoothed time between ticks, at
        least one period and at most ``max_contact_age_s`` (a tick comes by then, or the slide ends)."""
        return float(np.clip(self.interval_s, self.period_s, self.max_contact_age_s))

    def abort(self) -> None:
        """Stopped from outside (e-stop, watchdog, a target the arm cannot reach)."""
        self.stop = self.stop or self.servo.stopped

    def finish(self) -> list[FrameContact]:
        """Close the stream: the last good contact, if it is not the last one published."""
        last = self.last_good
        if last is not None and (not self.published or np.linalg.norm(
                self.published[-1].sense.point_xyz - last.sense.point_xyz) > 1e-9):
            self._emit(last)
        return self.take_published()

    def take_published(self) -> list[FrameContact]:
        """The stream's contacts not yet handed out, in order."""
        out, self._outbox = self._outbox, []
        return out

    def _emit(self, frame: FrameContact) -> None:
        self.published.append(frame)
        self._outbox.append(frame)

    # -- outcome ------------------------------------------------------------------
    @property
    def slid_m(self) -> float:
        """The planned length reached (the servo stopped on LENGTH), else the measured advance."""
        return self.length_m if self.stop is SlideStop.LENGTH else float(self.progress_m)

    @property
    def n_contacts(self) -> int:
        return len(self.published)

    @property
    def last_contact(self) -> Optional[FrameContact]:
        return self.published[-1] if self.published else None


def servo_step_trajectory(model: ArmModel, limits: MotionLimits, box: WorkspaceBox, ik: IKSettings,
                          q_now: np.ndarray, qd_now: Optional[np.ndarray], target_xyz: np.ndarray,
                          min_duration_s: float, max_joint_step_rad: float = 0.3) -> TimedTrajectory:
    """The replacing trajectory of one tick (module docstring): one point at rest, ``T`` s from the start.

    Raises:
        OutsideWorkspace: the target is outside the box.
        TrajectoryError: no IK solution (NoSolutionFound is one), or a joint jump above
            ``max_joint_step_rad`` (an IK branch flip is not a servo step).
    """
    target = np.asarray(target_xyz, dtype=float).reshape(3)
    box.check(target[None])
    q0 = np.asarray(q_now, dtype=float)
    try:
        q1 = solve_ik(model, target, q0, ik).q
    except ValueError as exc:  # NoSolutionFound
        raise TrajectoryError(str(exc)) from None
    _check_joint_jump(q0, q1, max_joint_step_rad)
    dq = q1 - q0
    tip0 = model.fk(q0)[0]
    dist = float(np.linalg.norm(target - tip0))
    a, v = limits.acceleration_rad_s2, limits.velocity_rad_s
    # from rest: |a| = 6|Δq|/T², |v| = 1.5|Δq|/T; the tip by the same 1.5 factor (a straight move)
    T = max(float(min_duration_s), float(np.max(np.sqrt(6.0 * np.abs(dq) / a))),
            float(np.max(1.5 * np.abs(dq) / v)), 1.5 * dist / limits.tip_speed_mps, 1e-3)
    starts = [np.zeros_like(q0)]
    if qd_now is not None and np.all(np.isfinite(qd_now)):
        starts.append(np.asarray(qd_now, dtype=float))
    zero = np.zeros_like(q0)
    for _ in range(60):
        if all(_within_joint_limits(limits, np.array([0.0, T]), np.vstack([q0, q1]), np.vstack([v0, zero]))
               for v0 in starts):
            break
        T *= 1.2
    else:
        raise TrajectoryError("servo step: no duration within the joint limits from the current velocity")
    return TimedTrajectory(np.array([T]), q1[None], zero[None], target[None])


def _check_joint_jump(q0: np.ndarray, q1: np.ndarray, max_joint_step_rad: float) -> None:
    """Raise TrajectoryError when a servo step moves a joint more than ``max_joint_step_rad`` (an IK
    branch flip is not a servo step)."""
    jump = float(np.max(np.abs(q1 - q0)))
    if jump > max_joint_step_rad:
        raise TrajectoryError(f"servo step: joint jump {jump:.3f} rad > {max_joint_step_rad}")


def _within_joint_limits(limits: MotionLimits, times_s: np.ndarray, q: np.ndarray, qd: np.ndarray) -> bool:
    """The cubic Hermite through (times, q, qd) keeps every joint within its velocity and acceleration caps."""
    vel, acc = hermite_extrema(times_s, q, qd)
    return bool(np.all(vel <= limits.velocity_rad_s * (1 - 1e-9)) and np.all(acc <= limits.acceleration_rad_s2 * (1 - 1e-9)))


def stopping_time_s(limits: MotionLimits, qd_rad_s: np.ndarray) -> float:
    """Shortest time to bring joint velocities ``qd`` to rest at constant deceleration within the caps:
    max_j |qd_j| / a_j (the Hermite segment q → q + qd·T/2, velocities qd → 0, decelerates at qd/T)."""
    return float(np.max(np.abs(np.asarray(qd_rad_s, dtype=float)) / limits.acceleration_rad_s2))


def _rest_point(limits: MotionLimits, q: np.ndarray, qd: np.ndarray) -> tuple[float, np.ndarray]:
    """(T_s, q + q̇ T_s / 2): where joints at ``q`` moving at ``qd`` come to rest, decelerating evenly
    in T_s = 1.05 × :func:`stopping_time_s` (5 % inside the caps)."""
    T_s = 1.05 * stopping_time_s(limits, qd)
    return T_s, q + 0.5 * T_s * qd


def cartesian_step(model: ArmModel, q_now: np.ndarray, target_xyz: np.ndarray, iterations: int = 4,
                   tol_m: float = 1e-8) -> np.ndarray:
    """Joints that move the tip centre from its place at ``q_now`` to the nearby ``target_xyz`` with
    the finger's orientation held: Newton steps Δq = J⁺ [e_p; e_R] (J the tip's 6×n Jacobian in world
    axes, e_p the position error, e_R = ½ Σᵢ rᵢ × r₀ᵢ the rotation error to the start). Unlike the
    IK (which stops within its tolerance and lets the tilt wander within its bound), successive steps
    are consistent to far below a micrometre, so a servo's 10 ms segments carry no IK noise."""
    q = np.asarray(q_now, dtype=float).copy()
    R0 = model.fk(q)[1]
    target = np.asarray(target_xyz, dtype=float).reshape(3)
    for _ in range(iterations):
        p, R, J = model.fk_jacobian(q)
        e_p = target - p
        e_r = 0.5 * np.cross(R, R0, axisa=0, axisb=0).sum(axis=0)
        if float(np.linalg.norm(e_p)) < tol_m and float(np.linalg.norm(e_r)) < 1e-9:
            break
        q = q + np.linalg.pinv(J) @ np.concatenate([e_p, e_r])
    return q


def servo_stream_trajectory(model: ArmModel, limits: MotionLimits, box: WorkspaceBox, ik: IKSettings,
                            q_now: np.ndarray, qd_now: Optional[np.ndarray], base_xyz: np.ndarray,
                            tip_velocity_xyz: np.ndarray, horizon_s: float,
                            max_joint_step_rad: float = 0.3, max_stretch: int = 16) -> TimedTrajectory:
    """The velocity-continuous replacing trajectory of one tick: two points.

    1. at T₁: the joints q₁ putting the tip at b + v T₁ (b = ``base_xyz``, v = ``tip_velocity_xyz``:
       where the tip would be after T₁ at the slide speed; :func:`cartesian_step` from ``q_now``,
       within ``ik.tol_m``), moving at the joint velocity q̇₁ = J⁺ [v; 0] (J the tip's 6×n Jacobian
       there: the finger's orientation held): the controller runs the cubic Hermite from its current state
       (position and velocity) into it, so a tick that replaces it before T₁ continues the motion
       instead of restarting it from rest; at the slide speed already, the segment has no
       acceleration at all;
    2. at T₁ + T_s: rest at q₁ + q̇₁ T_s / 2, T_s = max_j |q̇₁ⱼ| / aⱼ (even deceleration within the
       caps): if no further tick comes (a stalled commander), the arm stops by itself, a millimetre
       or so on.

    T₁ is the first of ``horizon_s``·1.25ᵏ (k < ``max_stretch``) whose segments, from ``qd_now``
    (None: from rest), keep every joint within its velocity and acceleration caps (from rest it takes
    longer: the arm speeds up over several ticks); the target and the stopping point must be inside
    the box and the joint limits, and |v| within ``limits.tip_speed_mps``.

    Raises:
        OutsideWorkspace: a target or the stopping point outside the box.
        TrajectoryError: no joint step to the target within ``ik.tol_m`` and the joint limits, a
            joint jump above ``max_joint_step_rad``, a speed above the tip speed, a stopping point
            beyond the joint limits, or no duration within the caps.
    """
    base = np.asarray(base_xyz, dtype=float).reshape(3)
    v = np.asarray(tip_velocity_xyz, dtype=float).reshape(3)
    if not (np.all(np.isfinite(v)) and float(np.linalg.norm(v)) <= limits.tip_speed_mps * (1 + 1e-9)):
        raise TrajectoryError(f"servo stream: tip velocity {v.tolist()} beyond {limits.tip_speed_mps} m/s")
    q0 = np.asarray(q_now, dtype=float)
    zero = np.zeros_like(q0)
    v0 = np.asarray(qd_now, dtype=float) if qd_now is not None and np.all(np.isfinite(qd_now)) else zero
    T1 = max(float(horizon_s), 1e-3)
    for _ in range(max_stretch):
        target = base + T1 * v
        box.check(target[None])
        q1 = cartesian_step(model, q0, target)
        if float(np.linalg.norm(model.fk(q1)[0] - target)) > ik.tol_m or not model.within_limits(q1):
            raise TrajectoryError("servo stream: no joint step to the target within the joint limits")
        _check_joint_jump(q0, q1, max_joint_step_rad)
        _, _, J = model.fk_jacobian(q1)
        qd1 = np.linalg.pinv(J) @ np.concatenate([v, np.zeros(3)])  # tip velocity v, orientation held
        if np.any(np.abs(qd1) > limits.velocity_rad_s * (1 - 1e-9)):
            raise TrajectoryError("servo stream: the tip velocity needs a joint velocity beyond its cap")
        T_s, q2 = _rest_point(limits, q1, qd1)
        if T_s < 1e-3:  # (nearly) no velocity: a millisecond's tail
            T_s, q2 = 1e-3, q1 + 0.5e-3 * qd1
        if _within_joint_limits(limits, np.array([0.0, T1, T1 + T_s]), np.vstack([q0, q1, q2]),
                                np.vstack([v0, qd1, zero])):
            break
        T1 *= 1.25
    else:
        raise TrajectoryError("servo stream: no duration within the joint limits from the current velocity")
    if not model.within_limits(q2):
        raise TrajectoryError("servo stream: the stopping point is beyond the joint limits")
    tip2 = model.fk(q2)[0]
    box.check(tip2[None])
    return TimedTrajectory(np.array([T1, T1 + T_s]), np.vstack([q1, q2]), np.vstack([qd1, zero]),
                           np.vstack([target, tip2]))


def stopping_trajectory(model: ArmModel, limits: MotionLimits, box: WorkspaceBox, q_now: np.ndarray,
                        qd_now: Optional[np.ndarray]) -> Optional[TimedTrajectory]:
    """Bring a moving arm to rest within the acceleration caps: one point at T_s, q + q̇ T_s / 2, at
    rest (the controller decelerates from its current state at q̇ / T_s). None: already (nearly) at
    rest, or the stopping point leaves the box or the joint limits (stop at once instead)."""
    if qd_now is None or not np.all(np.isfinite(qd_now)):
        return None
    T_s, q2 = _rest_point(limits, np.asarray(q_now, dtype=float), np.asarray(qd_now, dtype=float))
    if T_s < 1e-3:
        return None
    tip2 = model.fk(q2)[0]
    if not model.within_limits(q2) or not box.inside(tip2)[0]:
        return None
    return TimedTrajectory(np.array([T_s]), q2[None], np.zeros_like(q2)[None], tip2[None])


def tick_trajectory(model: ArmModel, limits: MotionLimits, box: WorkspaceBox, ik: IKSettings, q_now: np.ndarray,
                    qd_now: Optional[np.ndarray], loop: SlideLoop, step: SlideStep, stream: bool = True,
                    max_joint_step_rad: float = 0.3) -> TimedTrajectory:
    """The replacing trajectory of one tick (what the commander sends): velocity-continuous
    (:func:`servo_stream_trajectory`) while the servo steps along the surface and ``stream`` is on,
    its target ``loop.horizon_s`` of slide speed ahead of the measured tip (the servo's step
    stretched to the time the next tick will come); rest-ended (:func:`servo_step_trajectory`, the
    servo's target) while it regains the contact, or where the stream's stopping tail has no room
    (next to the box or a joint limit).

    Raises:
        OutsideWorkspace, TrajectoryError: as :func:`servo_step_trajectory`.
    """
    if stream and step.step_m > 0 and step.tangent_xyz is not None:
        speed, horizon = loop.config.slide_speed_mps, loop.horizon_s
        base = step.target_xyz - step.step_m * step.tangent_xyz  # the tip plus the servo's normal correction
        # The surface turns while the arm moves on what was sensed a tick ago: head along the chord to where
        # the tangent will be, s = v (lag + T₁/2) on (the lag ≈ one tick: ticks wait for a fresh frame).
        n = loop.servo.normal
        direction = step.tangent_xyz
        if n is not None:
            turned = _unit(step.tangent_xyz - loop.curvature_per_m * speed * 1.5 * horizon * n)
            direction = turned if turned is not None else direction
        try:
            return servo_stream_trajectory(model, limits, box, ik, q_now, qd_now, base, speed * direction,
                                           horizon, max_joint_step_rad)
        except (OutsideWorkspace, TrajectoryError):
            pass
    return servo_step_trajectory(model, limits, box, ik, q_now, qd_now, step.target_xyz, loop.period_s,
                                 max_joint_step_rad)
