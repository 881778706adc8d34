"""ArmCommander in one process (no other nodes): a slide's servo steps go out as replacing
trajectories, the e-stop and the joint-state watchdog stop a slide like any motion, and a motion
is judged late by the joint states read, not by a clock they lag behind."""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402

from tactile_driver.commander_api import ArmCommander, CommanderConfig, TaskResult  # noqa: E402
from tactile_driver.ik import IKSettings, solve_ik  # noqa: E402
from tactile_driver.slide_loop import FrameContact  # noqa: E402
from tactile_driver.slide_servo import ContactSense, SlideServoConfig, SlideStop  # noqa: E402


@pytest.fixture
def arm():
    rclpy.init()
    node = rclpy.create_node("slide_commander_test")
    cmd = ArmCommander(node, CommanderConfig(planar=True, watchdog_timeout_s=0.3, publish_fingertip_pose=False))
    sent = []
    cmd._pub_traj.publish = sent.append  # what would go to the controller
    cmd.sent = sent
    cmd.q0 = solve_ik(cmd.model, np.array([0.45, 0.0, 0.06]), cmd.home, IKSettings()).q
    try:
        yield cmd
    finally:
        node.destroy_node()
        rclpy.shutdown()


def _state(arm, t_s, q=None):
    q = arm.q0 if q is None else q
    msg = JointState(name=list(arm.model.joint_names), position=[float(v) for v in q],
                     velocity=[0.0] * arm.model.nq)
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t_s), int(round((t_s % 1) * 1e9))
    arm._on_joint_state(msg)


def _frame(arm, t_s):
    arm._slide.on_frame(FrameContact(t_s, ContactSense(np.array([0.46, 0.0, 0.06]), np.array([-1.0, 0, 0]), 0.15)))


@pytest.mark.parametrize("stream", [True, False])
def test_slide_steps_replace_each_other_then_the_estop_stops_it(arm, stream):
    """Streamed steps: the target reached moving at the slide speed, then a stopping tail at rest;
    rest-ended steps (slide.stream false): one point at rest."""
    import dataclasses

    arm.cfg = dataclasses.replace(arm.cfg, slide_stream=stream)
    _state(arm, 1.0)
    assert arm.slide(np.array([0.0, 1.0, 0.0]), 0.1, SlideServoConfig())
    start = arm._slide.start_s
    _frame(arm, start + 0.001)
    arm._slide_tick()
    arm._slide.next_tick_s = -np.inf  # the node clock does not move here: make the next tick due
    _frame(arm, start + 0.002)
    arm._slide_tick()
    steps = [m for m in arm.sent if m.points]
    assert len(steps) == 2 and all(len(m.points) == (2 if stream else 1) for m in steps)  # short, replacing
    assert all(not any(m.points[-1].velocities) for m in steps)  # each ends at rest
    if stream:  # moving at the slide speed at the first point: J v = 0.05 m/s along +y
        J = arm.model.fk_jacobian(np.array(steps[1].points[0].positions))[2][:3]
        v = J @ np.array(steps[1].points[0].velocities)
        np.testing.assert_allclose(v, [0.0, SlideServoConfig().slide_speed_mps, 0.0], atol=2e-3)
    t = steps[0].points[0].time_from_start
    assert t.sec == 0 and t.nanosec >= 10_000_000  # at least one tick long: the controller interpolates to it
    arm._on_estop(Bool(data=True))
    assert arm.is_task_complete() and arm.get_result() == TaskResult.ABORTED and arm.last_task.reason == "e-stop"
    assert arm.sent[-1].points == []  # stop and hold
    assert arm._slide is None and arm._slide_timer is None  # its loop and timer are gone
    assert arm.last_task.extra["stop"] in ("aborted", "length")
    assert not arm.slide(np.array([0.0, 1.0, 0.0]), 0.1, SlideServoConfig())  # refused while engaged


def test_a_moving_slide_slows_to_rest_before_it_ends_and_a_jammed_one_stops_at_once(arm):
    """The servo's stop while the arm moves: a trajectory to rest (even deceleration within the caps),
    the slide ends once the arm is at rest; a force above the band (jammed) stops at once."""
    _state(arm, 1.0)
    arm.qd = np.full(arm.model.nq, 0.05)  # moving
    assert arm.slide(np.array([0.0, 1.0, 0.0]), 0.1, SlideServoConfig(lap_radius_m=0.0))
    start = arm._slide.start_s
    arm._slide.servo.stopped = SlideStop.LENGTH  # the servo's next answer: stopped
    arm._slide.next_tick_s = -np.inf
    _frame(arm, start + 0.001)
    arm._slide_tick()
    assert not arm.is_task_complete() and arm._slide_stopping is not None
    stop = arm.sent[-1]
    assert len(stop.points) == 1 and not any(stop.points[0].velocities)
    arm._slide_stopping = (-np.inf, arm._slide_stopping[1])  # the node clock does not move here: rest reached
    arm._slide_tick()
    assert arm.is_task_complete() and arm.get_result() == TaskResult.SUCCEEDED and "length" in arm.last_task.reason
    # jammed: stop and hold at once
    assert arm.slide(np.array([0.0, 1.0, 0.0]), 0.1, SlideServoConfig(lap_radius_m=0.0))
    arm._slide.next_tick_s = -np.inf
    arm._slide.on_frame(FrameContact(arm._slide.start_s + 0.001, ContactSense(
        np.array([0.46, 0.0, 0.06]), np.array([-1.0, 0, 0]), 5.0)))
    arm._slide_tick()
    assert arm.is_task_complete() and "force" in arm.last_task.reason and arm.sent[-1].points == []


def test_stale_joint_states_stop_a_slide(arm):
    _state(arm, 1.0)
    assert arm.slide(np.array([0.0, 1.0, 0.0]), 0.1, SlideServoConfig())
    deadline = time.monotonic() + 5.0
    while not arm.is_task_complete() and time.monotonic() < deadline:
        time.sleep(0.05)
        arm._update()  # the control tick (steady clock): no joint state for longer than the watchdog
    assert arm.get_result() == TaskResult.ABORTED and "stale" in arm.last_task.reason
    assert arm.last_task.joint_states_lost and arm.sent[-1].points == []


def test_an_approach_toward_the_table_is_shortened_to_end_inside_the_box():
    """ArmCommander.approach: 4 cm straight down from 2.5 cm above the box floor goes 2.45 cm
    (the trajectory sent ends 0.5 mm above the floor, by forward kinematics), instead of being refused."""
    rclpy.init()
    node = rclpy.create_node("approach_depth_test")
    try:
        arm = ArmCommander(node, CommanderConfig(watchdog_timeout_s=5.0, publish_fingertip_pose=False))
        sent = []
        arm._pub_traj.publish = sent.append
        floor = arm.box.lower_xyz[2]
        arm.q0 = solve_ik(arm.model, np.array([0.45, 0.0, floor + 0.025]), arm.home, IKSettings()).q
        _state(arm, 1.0)
        assert arm.approach(np.array([0.0, 0.0, -1.0]), 0.04), arm.last_task.reason
        end_q = [p.positions for p in sent[-1].points][-1]
        end_z = arm.model.fk(np.array(end_q))[0][2]
        assert floor <= end_z == pytest.approx(floor + 5e-4, abs=2e-4)
    finally:
        node.destroy_node()
        rclpy.shutdown()


@pytest.mark.parametrize("stamps", ["node clock", "another clock"])
def test_a_motion_is_judged_late_by_the_joint_states_read_not_the_clock(arm, stamps):
    """A commander behind on its joint-state queue (a loaded machine: the clock's newest tick is read,
    the states queue up) must not abort a motion the arm is making on time: only a state stamped after
    the deadline and away from the goal is late. Stamps on another clock: judged by the clock."""
    now = [100.0]
    arm.now_s = lambda: now[0]
    _state(arm, 100.0)
    assert arm.follow_path(np.array([[0.45, 0.05, 0.06]]))
    traj = [np.array(p.positions) for p in arm.sent[-1].points]
    start, task = arm._task.start_s, arm._task
    deadline = start + task.traj.duration_s + arm.cfg.goal_time_tolerance_s
    offset = 0.0 if stamps == "node clock" else -1e6
    now[0] = deadline + 1.0  # the clock is past the deadline...
    _state(arm, offset + start + 0.5 * task.traj.duration_s, traj[len(traj) // 2])  # ...the states mid-motion
    arm._update()
    if stamps == "another clock":  # nothing to judge by but the clock
        assert arm.get_result() == TaskResult.ABORTED and "goal not reached" in arm.last_task.reason
        return
    assert not arm.is_task_complete()  # not late: the arm was on its way when this state was taken
    _state(arm, deadline + 0.5, traj[len(traj) // 2])  # a state after the deadline, short of the goal
    arm._update()
    assert arm.get_result() == TaskResult.ABORTED and "goal not reached" in arm.last_task.reason
    assert arm.sent[-1].points == []  # stopped


def test_a_lagging_reader_sees_a_motion_through_when_the_states_arrive(arm):
    now = [100.0]
    arm.now_s = lambda: now[0]
    _state(arm, 100.0)
    assert arm.follow_path(np.array([[0.45, 0.05, 0.06]]))
    traj = [np.array(p.positions) for p in arm.sent[-1].points]
    start, duration = arm._task.start_s, arm._task.traj.duration_s
    now[0] = start + duration + arm.cfg.goal_time_tolerance_s + 1.0
    for k, q in enumerate(traj):  # the queue drains: every state arrives after the deadline by the clock
        _state(arm, start + duration * k / (len(traj) - 1), q)
        arm._update()
    assert arm.get_result() == TaskResult.SUCCEEDED, arm.last_task.reason
