"""The graph slide's loop core (tactile_driver.slide_loop) over a fake clock, a fake arm and the
simulated sensor, against the offline slide (tactile_sim.slide) and independent checks; its
replacing trajectories against the independent TrajectoryMonitor; the touch cycle of a slide."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tactile_common import fields
from tactile_driver.commander_api import TaskResult
from tactile_driver.contact import ContactConfig, ContactDetector
from tactile_driver.ik import IKSettings, solve_ik
from tactile_driver.kinematics import ArmModel, home_configuration
from tactile_driver.safety import EStopLatch, OutsideWorkspace, WorkspaceBox
from tactile_driver.slide_loop import (FrameContact, SlideLoop, servo_step_trajectory, servo_stream_trajectory,
                                      stopping_trajectory, tick_trajectory)
from tactile_driver.slide_servo import ContactSense, ContactThinner, SlideServo, SlideServoConfig, SlideStop
from tactile_driver.taxels import load_layout
from tactile_driver.touch_executor import TouchExecutor, TouchRequest
from tactile_driver.trajectory import MotionLimits, TimedTrajectory
from tactile_driver.trajectory_monitor import TrajectoryMonitor
from tactile_common.params_file import package_config
from tactile_sim.sensor_model import SensorModel
from tactile_sim.slide import simulate_slide
from tactile_sim.controller import TrajectoryController
from tactile_sim.touch import simulate_approach

Z = 0.06
BOX = (np.array([0.25, -0.3, 0.0]), np.array([0.75, 0.3, 0.6]))


class Disc:
    dim = 2

    def __init__(self, c, r):
        self.c, self.r = np.asarray(c, float), float(r)

    def sdf(self, p):
        return np.linalg.norm(np.asarray(p)[:, :2] - self.c, axis=1) - self.r


@pytest.fixture(scope="module")
def layout():
    return load_layout(package_config("tactile_driver", "taxels_ring.yaml"))


def _approach(obj, layout, seed=0):
    model = SensorModel(layout, seed=seed)
    det = ContactDetector(layout, ContactConfig())
    rng = np.random.default_rng(seed)
    app = simulate_approach(obj, layout, model, det, np.array([0.43, 0.0, Z]), np.array([1.0, 0, 0]),
                            0.05, 0.0001, rng=rng)
    assert app.contact
    return model, det, rng, app


class FakeRig:
    """The simulated sensor at the fingertip, one frame per tick; the driver's per-frame stream
    reaches the loop ``latency`` ticks late; the arm moves ``response`` of the way to each target
    per tick (1 = it gets there within the tick)."""

    def __init__(self, obj, model, det, rng, tip, latency=0, response=1.0, silent_after=None):
        self.obj, self.model, self.det, self.rng = obj, model, det, rng
        self.tip = np.asarray(tip, float).copy()
        self.target = self.tip.copy()
        self.latency, self.response, self.silent_after = latency, response, silent_after
        self.queue = []
        self.forces = []

    def frame(self, t, k):
        was = self.det.in_contact
        self.det.update(self.model.frame(self.obj, self.tip, np.eye(3), self.rng))
        if self.det.in_contact and self.det.current is not None:
            p, n = self.det.current.to_world(self.tip, np.eye(3))
            self.queue.append(FrameContact(t, ContactSense(p, n, self.det.current.force_n)))
            self.forces.append(self.det.current.force_n)
        elif was:
            self.queue.append(FrameContact(t, None))
        if self.silent_after is not None and k >= self.silent_after:
            self.queue.clear()  # the driver fell silent
        out, self.queue = self.queue[:max(len(self.queue) - self.latency, 0)], self.queue[max(len(self.queue) - self.latency, 0):]
        return out

    def move(self):
        self.tip = self.tip + self.response * (self.target - self.tip)


def run_loop(loop, rig, period, max_ticks=20000):
    t = loop.start_s
    for k in range(max_ticks):
        for f in rig.frame(t, k):
            loop.on_frame(f)
        if loop.due(t):
            step = loop.tick(t, rig.tip)
            if step.target_xyz is not None:
                rig.target = np.asarray(step.target_xyz)
            if step.stop is not None:
                return step.stop, loop.finish()
        rig.move()
        t += period
    raise AssertionError("the slide did not stop")


def test_loop_without_latency_is_the_offline_slide(layout):
    """A perfect arm and no latency: the graph loop publishes exactly the offline slide's contacts."""
    obj, cfg = Disc([0.5, 0.0], 0.04), SlideServoConfig()
    model, det, rng, app = _approach(obj, layout)
    servo = SlideServo(cfg, np.array([0, -1.0, 0]), 0.15, *BOX, planar=True)
    offline = simulate_slide(obj, model, det, servo, ContactThinner(cfg.thin_distance_m, cfg.thin_angle_rad),
                             app.tip_xyz_at_stop, rng=np.random.default_rng(5))
    model, det, _, app = _approach(obj, layout)
    loop = SlideLoop(cfg, np.array([0, -1.0, 0]), 0.15, *BOX, start_s=10.0, planar=True)
    rig = FakeRig(obj, model, det, np.random.default_rng(5), app.tip_xyz_at_stop)
    stop, _ = run_loop(loop, rig, loop.period_s)
    assert stop is offline.stop is SlideStop.LENGTH
    got = np.array([f.sense.point_xyz for f in loop.published])
    np.testing.assert_allclose(got, offline.points_xyz, atol=1e-12)
    assert loop.slid_m == pytest.approx(offline.slid_m)


def test_loop_keeps_contact_with_latency_and_a_lagging_arm(layout):
    """Contacts three ticks late and an arm that covers 40 % of each step per tick: still in the
    band all round, the contacts on the circle every ~5 mm (the circle's SDF, not the code's)."""
    obj, cfg = Disc([0.5, 0.0], 0.04), SlideServoConfig()
    model, det, rng, app = _approach(obj, layout)
    loop = SlideLoop(cfg, np.array([0, -1.0, 0]), 0.12, *BOX, start_s=0.0, planar=True)
    rig = FakeRig(obj, model, det, rng, app.tip_xyz_at_stop, latency=3, response=0.4)
    stop, _ = run_loop(loop, rig, loop.period_s)
    assert stop is SlideStop.LENGTH
    f = np.array(rig.forces)
    k = int(np.argmax(f >= cfg.target_force_n * 0.9))
    assert f[k:].max() <= cfg.max_force_n and np.mean(f[k:] >= cfg.min_force_n) > 0.95
    P = np.array([fc.sense.point_xyz for fc in loop.published])
    assert np.abs(obj.sdf(P)).max() < 0.001
    gaps = np.linalg.norm(np.diff(P, axis=0), axis=1)[:-1]  # the last one closes the stream
    assert gaps.min() > 0.004 and gaps.max() < 0.007
    # the slide travelled its planned length although the arm lags: the contacts span ~0.12 m of arc
    arc = np.abs(np.diff(np.unwrap(np.arctan2(P[:, 1], P[:, 0] - 0.5)))).sum() * 0.04
    assert arc > 0.12 * 0.04 / 0.05 * 0.9


def test_a_release_then_silence_stops_the_slide_as_lost(layout):
    obj, cfg = Disc([0.5, 0.0], 0.04), SlideServoConfig(lost_ticks=10)
    model, det, rng, app = _approach(obj, layout)
    loop = SlideLoop(cfg, np.array([0, -1.0, 0]), 0.3, *BOX, start_s=0.0, planar=True, max_contact_age_s=0.05)
    rig = FakeRig(obj, model, det, rng, app.tip_xyz_at_stop, silent_after=40)
    stop, closing = run_loop(loop, rig, loop.period_s)
    assert stop is SlideStop.LOST
    assert loop.servo.ticks <= 40 + 0.05 / loop.period_s + cfg.lost_ticks + 2
    # the last good contact closes the stream
    assert loop.published[-1].stamp_s == loop.last_good.stamp_s


def test_the_servo_acts_once_per_fresh_frame_and_a_release_is_no_contact():
    cfg = SlideServoConfig()
    loop = SlideLoop(cfg, np.array([0, 1.0, 0]), 0.1, *BOX, start_s=1.0, planar=True, max_contact_age_s=0.1)
    sense = ContactSense(np.array([0.5, 0, Z]), np.array([-1.0, 0, 0]), 0.2)
    loop.on_frame(FrameContact(0.5, sense))  # before the slide: ignored
    assert loop.latest is None and not loop.due(1.0)
    loop.on_frame(FrameContact(1.01, sense))
    assert loop.due(1.02) and loop.current(1.02) is sense
    loop.tick(1.02, np.array([0.49, 0, Z]))  # acts on it: a command at 1.02
    assert not loop.due(1.05)  # no frame sensed since that command: wait for one
    loop.on_frame(FrameContact(1.03, sense))
    assert loop.due(1.05) and loop.current(1.05) is sense
    loop.tick(1.05, np.array([0.49, 0, Z]))
    assert not loop.due(1.1) and loop.due(1.16)  # silent for max_contact_age_s: go on without contact
    assert loop.current(1.16) is None
    loop.on_frame(FrameContact(1.17, None))  # a release
    assert loop.current(1.18) is None
    loop.on_frame(FrameContact(1.16, sense))  # out of order: the newer release stands
    assert loop.latest.sense is None


def test_ticks_follow_the_control_rate_and_skip_missed_ones():
    loop = SlideLoop(SlideServoConfig(control_rate_hz=100.0), np.array([0, 1.0, 0]), 0.1, *BOX, start_s=2.0,
                     max_contact_age_s=0.1)
    assert not loop.due(2.0) and loop.due(2.1)  # the first tick waits for the stream's first frame, a while
    loop.on_frame(FrameContact(2.0, ContactSense(np.array([0.5, 0, Z]), np.array([-1.0, 0, 0]), 0.2)))
    assert loop.due(2.0) and not loop.due(1.99)
    sense = ContactSense(np.array([0.5, 0, Z]), np.array([-1.0, 0, 0]), 0.2)
    loop.tick(2.0, np.array([0.5, 0, Z]))
    loop.on_frame(FrameContact(2.005, sense))
    assert not loop.due(2.005) and loop.due(2.01)
    loop.tick(2.5, np.array([0.5, 0, Z]))  # late by 49 ticks: the next is one period on, not a burst
    loop.on_frame(FrameContact(2.5, sense))
    assert not loop.due(2.504) and loop.due(2.51)


@pytest.fixture(scope="module")
def arm():
    from tactile_driver.kinematics import PANDA_FLANGE, PANDA_JOINTS

    model = ArmModel("", list(PANDA_JOINTS), PANDA_FLANGE, 0.16)
    limits = MotionLimits.for_model(model, [1.0] * 7, [2.0] * 7, 0.10)
    box = WorkspaceBox.from_params((0.25, 0.75), (-0.3, 0.3), (0.0, 0.6), 0.0, 0.005, 0.010)
    q0 = solve_ik(model, np.array([0.45, 0.0, Z]), home_configuration(model), IKSettings()).q
    return SimpleNamespace(model=model, limits=limits, box=box, q0=q0,
                           monitor=TrajectoryMonitor(model, limits, box))


@pytest.mark.parametrize("qd_scale", [0.0, 0.5, 1.0])
def test_servo_steps_stay_within_the_limits_from_any_velocity(arm, qd_scale):
    """Each replacing trajectory passes the independent monitor (from rest, as it assumes) and its
    Hermite segment from the measured velocity (what the controller runs) stays within the limits."""
    from scipy.interpolate import CubicHermiteSpline

    rng = np.random.default_rng(1)
    tip0 = arm.model.fk(arm.q0)[0]
    for _ in range(20):
        qd = qd_scale * rng.uniform(-1, 1, 7) * arm.limits.velocity_rad_s * 0.9
        target = tip0 + rng.uniform(-1, 1, 3) * 5e-4
        traj = servo_step_trajectory(arm.model, arm.limits, arm.box, IKSettings(), arm.q0, qd, target, 0.01)
        assert traj.times_s[0] >= 0.01 and np.all(traj.velocities_rad_s == 0)
        assert arm.monitor.check(list(arm.model.joint_names), traj.times_s, traj.positions_rad,
                                 traj.velocities_rad_s, q_now=arm.q0) == []
        np.testing.assert_allclose(arm.model.fk(traj.positions_rad[-1])[0], target, atol=2e-4)
        spline = CubicHermiteSpline([0.0, traj.times_s[0]], np.vstack([arm.q0, traj.positions_rad[0]]),
                                    np.vstack([qd, np.zeros(7)]))
        ts = np.linspace(0, traj.times_s[0], 400)
        assert np.all(np.abs(spline(ts, 1)) <= arm.limits.velocity_rad_s * (1 + 1e-6))
        assert np.all(np.abs(spline(ts, 2)) <= arm.limits.acceleration_rad_s2 * (1 + 1e-6))


def test_a_servo_step_outside_the_box_is_refused(arm):
    with pytest.raises(OutsideWorkspace):
        servo_step_trajectory(arm.model, arm.limits, arm.box, IKSettings(), arm.q0, None,
                              np.array([0.2, 0.0, Z]), 0.01)


def _monitor_ok(arm, traj, q, qd):
    found = arm.monitor.check(list(arm.model.joint_names), traj.times_s, traj.positions_rad, traj.velocities_rad_s,
                              q_now=q, qd_now=qd)
    assert found == [], "\n".join(map(str, found))


@pytest.mark.parametrize("qd_scale", [0.0, 0.02, 0.05])  # the slide speed is ~0.03 of the caps
def test_streamed_steps_reach_the_target_moving_then_stop_within_the_limits(arm, qd_scale):
    """The velocity-continuous step: through b + v T₁ at the asked tip velocity (J q̇ = v, the
    finger's orientation held), then at rest a little further on; every segment, from the measured
    state (position and velocity), within the limits by the independent monitor."""
    rng = np.random.default_rng(2)
    tip0, R0 = arm.model.fk(arm.q0)
    for _ in range(20):
        qd = qd_scale * rng.uniform(-1, 1, 7) * arm.limits.velocity_rad_s
        d = rng.normal(size=3)
        v = 0.05 * d / np.linalg.norm(d)
        traj = servo_stream_trajectory(arm.model, arm.limits, arm.box, IKSettings(), arm.q0, qd, tip0, v, 0.02)
        T1 = traj.times_s[0]
        assert len(traj.times_s) == 2 and T1 >= 0.02
        _monitor_ok(arm, traj, arm.q0, qd)
        p1, R1 = arm.model.fk(traj.positions_rad[0])
        np.testing.assert_allclose(p1, tip0 + T1 * v, atol=1e-6)
        np.testing.assert_allclose(R1, R0, atol=1e-6)
        J = arm.model.fk_jacobian(traj.positions_rad[0])[2]
        np.testing.assert_allclose(J @ traj.velocities_rad_s[0], np.r_[v, 0, 0, 0], atol=1e-9)
        assert np.all(traj.velocities_rad_s[1] == 0)
        tail = np.linalg.norm(arm.model.fk(traj.positions_rad[1])[0] - p1)
        assert tail < 0.003  # stops within a few millimetres of the target
    if qd_scale == 0.0:  # at the slide speed already: no stretch, and no acceleration on the segment
        q1, qd1 = traj.positions_rad[0], traj.velocities_rad_s[0]
        again = servo_stream_trajectory(arm.model, arm.limits, arm.box, IKSettings(), q1, qd1,
                                        arm.model.fk(q1)[0], v, 0.01)
        assert again.times_s[0] == pytest.approx(0.01)


def test_a_streamed_step_whose_stopping_tail_leaves_the_box_is_refused(arm):
    q = solve_ik(arm.model, np.array([0.7495, 0.0, Z]), arm.q0, IKSettings()).q
    J = arm.model.fk_jacobian(q)[2]
    qd = np.linalg.pinv(J) @ np.r_[0.05, 0, 0, 0, 0, 0]  # already at the slide speed: no stretch
    with pytest.raises(OutsideWorkspace):  # the target (0.7500) is inside; the tail would cross x = 0.75
        servo_stream_trajectory(arm.model, arm.limits, arm.box, IKSettings(), q, qd,
                                np.array([0.7495, 0.0, Z]), np.array([0.05, 0.0, 0.0]), 0.01)


def test_a_moving_arm_is_brought_to_rest_within_the_limits(arm):
    rng = np.random.default_rng(3)
    assert stopping_trajectory(arm.model, arm.limits, arm.box, arm.q0, np.zeros(7)) is None
    for _ in range(10):
        qd = rng.uniform(-0.2, 0.2, 7)
        stop = stopping_trajectory(arm.model, arm.limits, arm.box, arm.q0, qd)
        assert stop is not None and np.all(stop.velocities_rad_s == 0)
        _monitor_ok(arm, stop, arm.q0, qd)
        dec = np.abs(qd) / stop.times_s[0]  # the Hermite segment decelerates evenly
        assert np.all(dec <= arm.limits.acceleration_rad_s2) and dec.max() > 0.9 * arm.limits.acceleration_rad_s2.min()


class JointRig(FakeRig):
    """FakeRig whose tip is the forward kinematics of the simulated joint_trajectory_controller
    (tactile_sim.controller) running the trajectories the commander sends."""

    def __init__(self, obj, model, det, rng, arm, q0, latency):
        super().__init__(obj, model, det, rng, arm.model.fk(q0)[0], latency=latency)
        self.arm = arm
        self.ctrl = TrajectoryController(arm.model.joint_names, q0)

    def at(self, t):
        q, qd = self.ctrl.state(t)
        self.tip = self.arm.model.fk(q)[0]
        return q, qd


def run_joint_loop(loop, rig, stream, frame_s=0.005, max_frames=20000):
    """The commander's slide over the simulated controller: frames every ``frame_s`` (the sensor's
    200 Hz), ticks when due, each tick's trajectory (tick_trajectory) checked by the monitor from the
    measured state and run. Returns (stop, slide time (s), tip speeds along the way)."""
    names = list(rig.arm.model.joint_names)
    t = loop.start_s
    for k in range(max_frames):
        q, qd = rig.at(t)
        for f in rig.frame(t, k):
            loop.on_frame(f)
        if loop.due(t):
            step = loop.tick(t, rig.tip)
            if step.stop is not None:
                return step.stop, t - loop.start_s
            traj = tick_trajectory(rig.arm.model, rig.arm.limits, rig.arm.box, IKSettings(), q, qd, loop, step, stream)
            _monitor_ok(rig.arm, traj, q, qd)
            rig.ctrl.command(t, names, traj.times_s, traj.positions_rad, traj.velocities_rad_s)
        t += frame_s
    raise AssertionError("the slide did not stop")


@pytest.mark.parametrize("stream", [True, False])
def test_a_slide_over_the_simulated_controller_keeps_contact_and_streamed_moves_at_the_slide_speed(
        layout, arm, stream):
    """Frames two sensor periods late, ticks paced by them (~10–15 ms): streamed steps slide at
    ≥ 80 % of slide_speed_mps, rest-ended ones far slower; both keep the force band on the circle."""
    obj, cfg = Disc([0.5, 0.0], 0.04), SlideServoConfig()
    model, det, rng, app = _approach(obj, layout)
    q0 = solve_ik(arm.model, app.tip_xyz_at_stop, arm.q0, IKSettings()).q
    loop = SlideLoop(cfg, np.array([0, -1.0, 0]), 0.08, *BOX, start_s=0.0, planar=True)
    rig = JointRig(obj, model, det, rng, arm, q0, latency=2)
    stop, duration_s = run_joint_loop(loop, rig, stream)
    assert stop is SlideStop.LENGTH
    speed = loop.progress_m / duration_s
    if stream:
        assert speed >= 0.8 * cfg.slide_speed_mps, speed
    else:
        assert speed < 0.6 * cfg.slide_speed_mps, speed
    f = np.array(rig.forces)
    k = int(np.argmax(f >= cfg.target_force_n * 0.9))
    assert f[k:].max() <= cfg.max_force_n and np.mean(f[k:] >= cfg.min_force_n) > 0.95
    P = np.array([fc.sense.point_xyz for fc in loop.published])
    assert np.abs(obj.sdf(P)).max() < 0.001 and len(P) >= 10
    # the sensed tangent turns by 1 / (disc radius + tip radius) per metre the tip centre slides
    assert loop.curvature_per_m == pytest.approx(1.0 / (0.04 + layout.tip_radius_m), rel=0.25)


# -- the touch cycle of a slide (TouchExecutor over a scripted arm) -------------------------------

def _traj(length_m):
    tip = np.array([[0.0, 0.0, 0.0], [length_m, 0.0, 0.0]])
    return TimedTrajectory(np.array([0.0, 1.0]), np.zeros((2, 7)), np.zeros((2, 7)), tip)


class ScriptedArm:
    def __init__(self, results):
        self.results = list(results)
        self.calls = []
        self.cfg = SimpleNamespace(dry_run=False, approach_speed_mps=0.02, approach_step_m=0.005)
        self.estop = EStopLatch()
        self.model = SimpleNamespace(fk=lambda q: (np.array([0.4, 0.2, 0.06]), np.eye(3)))
        self.tip_xyz = np.array([0.4, 0.2, 0.06])
        self.odometer_m = self.motion_time_s = self.t = 0.0
        self._last = None

    def now_s(self):
        return self.t

    def approach_depth_m(self, start_xyz, direction_xyz, depth_m, min_depth_m=0.0):
        return depth_m  # the box never shortens an approach here

    def plan(self, path, q_start=None, speed_mps=None, step_m=None, axes_xyz=None):
        self.calls.append(("plan", np.asarray(path).reshape(-1, 3)[-1].copy()))
        return _traj(0.1)

    def _verb(self, name, length, extra=None, contact_xyz=None):
        self.calls.append(name)
        result = self.results.pop(0)
        contact = None
        if contact_xyz is not None:
            contact = np.zeros((), dtype=fields.CONTACT_DTYPE)[()]
            contact["x"], contact["y"], contact["z"], contact["label"] = *contact_xyz, fields.LABEL_CONTACT
        self.odometer_m += length
        self.motion_time_s += 0.3
        self._last = SimpleNamespace(result=result, reason=result.name, traj=_traj(length), contact=contact,
                                     contact_stamp_ns=42 if contact is not None else 0, extra=extra or {})
        return True

    def follow_path(self, path, axes_xyz=None):
        return self._verb("follow_path", 0.3)

    def approach(self, direction, depth, q_start=None):
        self.depth = depth
        hit = self.results[0] == TaskResult.CONTACT
        return self._verb("approach", 0.02, contact_xyz=[0.45, 0.2, 0.06] if hit else None)

    def slide(self, direction, length, servo, normal_xyz=None):
        self.slide_args = (np.asarray(direction), length, servo)
        self.slide_normal = None if normal_xyz is None else np.asarray(normal_xyz)
        last = FrameContact(9.5, ContactSense(np.array([0.46, 0.25, 0.06]), np.array([-1.0, 0, 0]), 0.15))
        return self._verb("slide", 0.1, extra=dict(stop="length", slid_m=0.1, contacts=20, last_contact=last))

    def back_off(self, contact_xyz, clearance_m, contact_stamp_ns=None):
        self.back_off_args = (np.asarray(contact_xyz), clearance_m)
        self.back_off_xyz = np.asarray(contact_xyz) + [-0.02, 0.0, 0.0]
        return self._verb("back_off", 0.02)

    def retract(self):
        return self._verb("retract", 0.02)

    def is_task_complete(self):
        return True

    def get_result(self):
        return self._last.result

    @property
    def last_task(self):
        return self._last


def _run_slide(arm):
    done, free = [], []
    ex = TouchExecutor(arm, 0.03, 0.5, lambda *a: free.append(a), done.append, back_off_clearance_m=0.01,
                       slide_servo=SlideServoConfig(), slide_approach_length_m=0.07)
    ex.submit(TouchRequest(7, np.array([0.4, 0.2, 0.06]), np.array([1.0, 0.0, 0.0]), np.zeros((1, 3)),
                           np.array([0.0, 1.0, 0.0]), 0.1))
    for _ in range(10):
        arm.t += 0.3
        ex.update()
    return done, free


def test_slide_touch_approaches_deeper_slides_backs_off_and_reports_the_stream():
    arm = ScriptedArm([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.SUCCEEDED, TaskResult.SUCCEEDED])
    done, free = _run_slide(arm)
    assert [c for c in arm.calls if not isinstance(c, tuple)] == ["follow_path", "approach", "slide", "back_off"]
    assert arm.depth == 0.07  # standoff + the servo's approach depth, not a poke's
    np.testing.assert_allclose(arm.calls[1][1], [0.47, 0.2, 0.06])  # validated at the slide's approach depth
    assert arm.slide_args[1] == 0.1
    np.testing.assert_allclose(arm.slide_normal, [-1.0, 0.0, 0.0])  # the approach's, reversed (rim contacts)
    np.testing.assert_allclose(arm.back_off_args[0], [0.46, 0.25, 0.06])  # off the slide's last contact
    r = done[0]
    assert (r.outcome, r.first_observation_stamp_ns, r.observation_stamp_ns) == ("contact", 42, 9_500_000_000)
    assert (r.slide_m, r.slide_stop, r.contacts) == (0.1, "length", 21)
    np.testing.assert_allclose(r.end_xyz_m, [0.44, 0.25, 0.06])
    back = type(r).from_values(r.outcome.value, r.values())  # through /arm/touch_done's key/values
    assert (back.slide_m, back.slide_stop, back.first_observation_stamp_ns, back.contacts) == (0.1, "length", 42, 21)
    assert back.is_slide and not type(r)(1, r.outcome, "", 5, 0.0, 0.0).is_slide
    assert "slide_m" not in type(r)(1, r.outcome, "", 5, 0.0, 0.0).values()  # a poke's report is unchanged


def test_slide_touch_in_free_space_stays_at_the_probe_end():
    arm = ScriptedArm([TaskResult.SUCCEEDED, TaskResult.SUCCEEDED])
    done, free = _run_slide(arm)
    assert [c for c in arm.calls if not isinstance(c, tuple)] == ["follow_path", "approach"]  # no retract
    assert len(free) == 1 and done[0].outcome == "free_space" and done[0].first_observation_stamp_ns is None


def test_an_aborted_slide_aborts_the_touch():
    arm = ScriptedArm([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.ABORTED])
    done, _ = _run_slide(arm)
    assert done[0].outcome == "aborted" and done[0].reason.startswith("slide")
    assert "back_off" not in arm.calls
