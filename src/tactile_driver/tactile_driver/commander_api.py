"""ArmCommander: a small Python API over ros2_control's topic interface (nav2_simple_commander style).

Verbs start a motion and return at once (``True`` = accepted); poll
``is_task_complete()`` and read ``get_result()`` (a :class:`TaskResult`), or
call ``wait_until_complete(timeout_s)`` from a script that owns the node.

    arm = ArmCommander(node, CommanderConfig())
    arm.follow_path(path_xyz)                  # tip polyline, world frame
    arm.wait_until_complete(30.0)
    arm.approach(direction_xyz, max_depth_m)   # stops on the first contact
    ...
    arm.retract()                              # back to where the approach began
    arm.back_off(contact_xyz, clearance_m)     # away from a contact met on a path
    arm.slide(direction_xyz, length_m, servo)  # after an approach's contact: follow the surface

Everything goes through two topics: JointTrajectory out (a new trajectory
replaces the current one; an empty one stops and holds) and JointState in.
Safety (always on): every tip waypoint must lie in the workspace box
(rejected, never clamped); IK failures reject the motion before anything is
sent; ``/arm/estop`` (latched Bool) stops and refuses motion until released;
joint states older than ``watchdog_timeout_s`` (steady clock, so it also
fires when a simulated clock stops) stop the motion within one
``control_period_s``; an approach (the guarded move) stops when the sensor
driver has judged no frame for ``sensor_silence_s`` (node clock): a blind
finger must not press on (:attr:`sensor_silent_s`, ``_Task.sensor_lost``). With ``dry_run`` the planned trajectory goes to the
inspection topic only and the task completes at once.

A slide (:mod:`tactile_driver.slide_loop`) is a closed loop at the servo's
``control_rate_hz`` on the node clock: each tick sends one short replacing
trajectory (the IK of the servo's next target), so the e-stop and the
watchdog stop it like any motion; the per-frame contacts come from the
driver on ``/tactile/contact_frames`` and the thinned stream goes out
through ``on_slide_contact``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from tactile_common import fields, qos, topics
from tactile_common.pointcloud import PointCloudError, from_pointcloud2
from tactile_common.stamps import ns_from_s, stamp_s, time_from_ns
from tactile_common.wrist import PANDA_WRIST_BANDS_FLAT_M
from tactile_driver import arm_msgs
from tactile_driver.contact import back_off_target
from tactile_driver.arm_motions import ArmMotions, path_point_before, timed_start_ns
from tactile_driver.ik import tilt_of
from tactile_driver.kinematics import PANDA_FLANGE, PANDA_JOINTS
from tactile_driver.safety import EStopLatch, OutsideWorkspace, Watchdog
from tactile_driver.slide_loop import FrameContact, SlideLoop, stopping_trajectory, tick_trajectory
from tactile_driver.slide_servo import ContactSense, SlideServoConfig, SlideStop
from tactile_driver.trajectory import TimedTrajectory, TrajectoryError

# Joint states stamped further behind the node clock than this are taken as on another clock (the STATE
# queue holds 10 s at 100 Hz: a reader can be that far behind and still be reading the node clock).
MAX_STATE_LAG_S = 10.0


class TaskResult(enum.Enum):
    UNKNOWN = 0
    SUCCEEDED = 1  # reached the end of the motion
    CONTACT = 2  # an approach stopped on a contact
    REJECTED = 3  # not attempted: outside the box, IK failed, e-stop engaged, no joint state
    CANCELED = 4  # stop() was called
    ABORTED = 5  # e-stop, stale joint states, or the goal not reached in time


@dataclass
class CommanderConfig:
    """Everything the commander needs (the node fills it from its parameters)."""

    urdf_path: str = ""
    joint_names: tuple = PANDA_JOINTS
    flange_frame: str = PANDA_FLANGE
    tip_offset_m: float = 0.16
    home_rad: tuple = (0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854)
    box_x_m: tuple = (0.25, 0.75)
    box_y_m: tuple = (-0.30, 0.30)
    box_z_m: tuple = (0.0, 0.60)
    table_z_m: float = 0.0
    table_margin_m: float = 0.005
    tip_radius_m: float = 0.010
    tip_speed_mps: float = 0.10
    approach_speed_mps: float = 0.02
    max_joint_velocity_rad_s: tuple = (1.0,) * 7
    max_joint_acceleration_rad_s2: tuple = (2.0,) * 7
    waypoint_step_m: float = 0.01
    approach_step_m: float = 0.005
    max_joint_step_rad: float = 0.3
    ik_tol_m: float = 1e-4
    max_tilt_rad: float = 0.10
    wrist_bands_m: tuple = PANDA_WRIST_BANDS_FLAT_M  # the links behind the flange (tactile_common.wrist)
    goal_tolerance_rad: float = 0.002
    goal_time_tolerance_s: float = 2.0
    contact_latency_s: float = 0.25
    sensor_confirm_timeout_s: float = 10.0  # a driver that has not judged the end of an approach by then: abort
    sensor_silence_s: float = 0.25  # a moving approach with the driver's frames this far behind: stop (0 = off)
    start_lead_s: float = 0.0  # > 0: trajectories start this long after they are sent (header.stamp), not on receipt
    start_grid_s: float = 0.0  # > 0: and on a multiple of this (the simulated rig's tick), for identical sampling
    watchdog_timeout_s: float = 0.5
    control_period_s: float = 0.01
    dry_run: bool = False
    trajectory_topic: str = topics.JOINT_TRAJECTORY
    planned_topic: str = "~/planned_trajectory"
    publish_fingertip_pose: bool = True
    planar: bool = False  # 2D rig: slides stay in the x-y plane
    slide_max_contact_age_s: float = 0.25  # a slide's latest contact frame older than this: no contact
    slide_stream: bool = True  # velocity-continuous servo steps (slide_loop.servo_stream_trajectory)


@dataclass
class _Task:
    kind: str
    traj: TimedTrajectory
    start_s: float
    contact_start_s: float = np.inf
    result: TaskResult = TaskResult.UNKNOWN
    contact: Optional[np.ndarray] = None  # the CONTACT_DTYPE record that stopped it
    contact_stamp_ns: int = 0
    reason: str = ""
    joint_states_lost: bool = False  # ended for stale/missing joint states: worth a retry once they flow
    sensor_lost: bool = False  # an approach stopped because the sensor fell silent: worth a retry once it is back
    extra: dict = field(default_factory=dict)


class ArmCommander:
    """Verbs on the arm through ros2_control's topics; see the module docstring."""

    def __init__(self, node: Node, config: CommanderConfig,
                 on_state: Optional[Callable[[np.ndarray, np.ndarray, object], None]] = None) -> None:
        self.node = node
        self.cfg = c = config
        self.log = node.get_logger()
        self.motions = ArmMotions(c)  # the plans every verb sends (ROS-free; the offline rig uses it too)
        self.model, self.box, self.limits = self.motions.model, self.motions.box, self.motions.limits
        self.ik, self.home = self.motions.ik, self.motions.home
        self.estop = EStopLatch()
        self.watchdog = Watchdog(c.watchdog_timeout_s)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._last_tick_s = self._steady_s()
        self.q: Optional[np.ndarray] = None  # measured joints
        self.q_stamp_s = -np.inf  # their stamp (the controller's clock)
        self.sensor_decided_s = -np.inf  # the driver has judged every frame up to this stamp...
        self.sensor_contacts_sent = 0  # ...having sent this many contacts by then
        self.contacts_received = 0  # contact clouds (label 1) received from the driver
        self.acted_through_s = -np.inf  # every frame to here judged, its contacts acted on (published)
        self.tip_xyz: Optional[np.ndarray] = None
        self.odometer_m = 0.0  # tip path length over all measured states
        self.motion_time_s = 0.0  # time spent in motions (robot time, without timed-start waits)
        self.approach_origin_xyz: Optional[np.ndarray] = None
        self.approach_origin_q: Optional[np.ndarray] = None
        self.back_off_xyz: Optional[np.ndarray] = None
        self._task: Optional[_Task] = None
        self._dry_q: Optional[np.ndarray] = None  # dry run: end of the last plan (the arm "is" there)
        self._last: Optional[_Task] = None
        self.counters = {"invalid_joint_states": 0, "invalid_contacts": 0, "stops": 0, "rejected": 0}
        self._on_state = on_state
        self._slide: Optional[SlideLoop] = None
        self._slide_timer = None
        self._slide_stopping: Optional[tuple[float, str]] = None  # (rest by, s; why the servo stopped)
        self.qd: Optional[np.ndarray] = None  # measured joint velocities (None if not sent)
        self._own_contact_ns: set[int] = set()  # stamps of the slide contacts this commander published
        #: called with each FrameContact of a slide's thinned stream (the node publishes it)
        self.on_slide_contact: Optional[Callable[[FrameContact], None]] = None
        self._pub_traj = node.create_publisher(JointTrajectory, c.trajectory_topic, qos.COMMANDS)
        self._pub_planned = node.create_publisher(JointTrajectory, c.planned_topic, qos.EVENTS)
        self._pub_pose = node.create_publisher(
            arm_msgs.PoseStamped, topics.FINGERTIP_POSE, qos.STATE) if c.publish_fingertip_pose else None
        self._pub_acted = node.create_publisher(DiagnosticStatus, topics.ARM_ACTED, qos.SENSOR)
        node.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state, qos.STATE)
        node.create_subscription(PointCloud2, topics.CONTACTS, self._on_contacts, qos.OBSERVATIONS)
        node.create_subscription(Bool, topics.ESTOP, self._on_estop, qos.LATCHED)
        node.create_subscription(DiagnosticStatus, topics.SENSOR_DECIDED, self._on_sensor_decided, qos.SENSOR)
        node.create_subscription(PointCloud2, topics.CONTACT_FRAMES, self._on_contact_frame, qos.STATE)
        node.create_timer(c.control_period_s, self._update, clock=self._steady)

    # -- verbs ------------------------------------------------------------------
    def follow_path(self, path_xyz: np.ndarray, axes_xyz: Optional[np.ndarray] = None) -> bool:
        """Move the tip along a polyline (K, 3), world frame, at up to ``tip_speed_mps``; with ``axes_xyz``
        (K, 3) the finger axis at each point (:meth:`ArmMotions.tip_path`; None: vertical)."""
        path = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
        try:
            traj = self.plan(path, axes_xyz=axes_xyz) if axes_xyz is not None else None
        except (OutsideWorkspace, TrajectoryError) as exc:
            return self._reject("follow_path", str(exc))
        return self._start("follow_path", path, self.cfg.tip_speed_mps, self.cfg.waypoint_step_m, traj=traj)

    def approach(self, direction_xyz: np.ndarray, max_depth_m: float, q_start: Optional[np.ndarray] = None) -> bool:
        """Guarded move along ``direction_xyz`` (world) for ``max_depth_m`` at ``approach_speed_mps``,
        shortened to end inside the safety box (:meth:`ArmMotions.approach_depth_m`).

        Ends as CONTACT on the first label-1 point on /tactile/contacts (the
        arm is stopped at once), or SUCCEEDED at full depth. ``retract()``
        returns to the start of the approach. ``q_start``: plan from these joints instead of the
        measured ones (the arm is there within the goal tolerance: a repeated approach after its
        retract is then the same motion, whenever the last joint state was sampled).
        """
        d = np.asarray(direction_xyz, dtype=float).reshape(3)
        n = np.linalg.norm(d)
        if not np.isfinite(n) or n < 1e-9 or not max_depth_m > 0:
            return self._reject("approach", "direction must be a non-zero vector and max depth positive")
        if self.tip_xyz is None and not self.cfg.dry_run:
            return self._reject("approach", "no joint state yet")
        if q_start is not None:
            q_origin = np.array(q_start, dtype=float)
            origin = self.model.fk(q_origin)[0]
        else:
            q_origin, origin = self._plan_start()
        try:
            depth_m = self.approach_depth_m(origin, d, max_depth_m)
        except OutsideWorkspace as exc:
            return self._reject("approach", str(exc))
        end = self.motions.into_box(origin) + d / n * depth_m
        ok = self._start("approach", end, self.cfg.approach_speed_mps, self.cfg.approach_step_m, q_start=q_start)
        if ok:
            self.approach_origin_xyz, self.approach_origin_q = origin, np.array(q_origin, dtype=float)
        return ok

    def approach_depth_m(self, start_xyz: np.ndarray, direction_xyz: np.ndarray, depth_m: float,
                         min_depth_m: float = 0.0) -> float:
        """The depth an approach from ``start_xyz`` gets (:meth:`ArmMotions.approach_depth_m`; raises
        OutsideWorkspace below ``min_depth_m``)."""
        return self.motions.approach_depth_m(start_xyz, direction_xyz, depth_m, min_depth_m)

    def retract(self) -> bool:
        """Back to the joint configuration where the last approach began, at approach speed.

        In joint space, so the arm ends exactly where the approach started
        whatever the contact and its stopping latency were: the next touch is
        planned from the same joints on every run (determinism), and the tip
        path stays within a fraction of a millimetre of the approach line (a
        few centimetres of motion). Every tip waypoint is checked against the box.
        """
        if self.approach_origin_xyz is None:
            return self._reject("retract", "no approach to retract from")
        try:
            traj = self.plan_joint_move(self.approach_origin_q, self.cfg.approach_speed_mps, self.cfg.approach_step_m)
        except (OutsideWorkspace, TrajectoryError) as exc:
            return self._reject("retract", str(exc))
        return self._start("retract", None, self.cfg.approach_speed_mps, self.cfg.approach_step_m, traj=traj)

    def plan_joint_move(self, q_goal: np.ndarray, speed_mps: float, step_m: float) -> TimedTrajectory:
        """A joint-space straight line from the planning start to ``q_goal`` (:meth:`ArmMotions.joint_move`).
        Raises OutsideWorkspace."""
        return self.motions.joint_move(self._plan_start()[0], q_goal, speed_mps, step_m)

    def back_off(self, contact_xyz: np.ndarray, clearance_m: float, contact_stamp_ns: Optional[int] = None) -> bool:
        """Leave a contact met on a free-space path, at approach speed. Contacts are ignored meanwhile.

        When the last task was that path and ``contact_stamp_ns`` is given: back along the path, in
        joint space, to its last waypoint at least ``clearance_m`` of travel before the contact
        (the path was free there), or to its start when the contact came sooner
        (:func:`~tactile_driver.arm_motions.path_point_before`), so the arm ends on joints that do
        not depend on how late it stopped. Otherwise straight away from the contact to
        :func:`~tactile_driver.contact.back_off_target` at ``tip_radius_m + clearance_m``: the tip
        ends ``clearance_m`` off the surface.
        """
        if not clearance_m >= 0:
            return self._reject("back_off", "clearance must be >= 0")
        q_back = self._path_point_before(contact_stamp_ns, clearance_m)
        if q_back is not None:
            try:
                traj = self.plan_joint_move(q_back, self.cfg.approach_speed_mps, self.cfg.approach_step_m)
            except (OutsideWorkspace, TrajectoryError) as exc:
                return self._reject("back_off", str(exc))
            self.back_off_xyz = self.model.fk(q_back)[0]  # the nominal end of the move (the touch cycle reports it)
            return self._start("back_off", None, self.cfg.approach_speed_mps, self.cfg.approach_step_m, traj=traj)
        target = back_off_target(contact_xyz, self._plan_start()[1], self.cfg.tip_radius_m + clearance_m)
        if target is None:
            return self._reject("back_off", "needs a finite contact point away from the tip centre")
        self.back_off_xyz = target
        return self._start("back_off", target[None], self.cfg.approach_speed_mps, self.cfg.approach_step_m)

    def slide(self, direction_xyz: np.ndarray, length_m: float, servo: SlideServoConfig,
              normal_xyz: Optional[np.ndarray] = None) -> bool:
        """Slide along the surface from where the tip is (after an approach's contact), at most
        ``length_m`` in ``direction_xyz`` (projected on the sensed tangent), by the servo's rules;
        ``normal_xyz``: the normal to servo on until a contact has one (the approach's, reversed).

        Ends SUCCEEDED when a stop rule of the servo ends it (``last_task.extra``: ``stop``,
        ``slid_m``, ``contacts``, ``last_contact`` (a FrameContact or None), ``tip_path``), ABORTED
        on e-stop, stale joint states or a target the arm cannot reach. Not in dry run.
        """
        if self.cfg.dry_run:
            return self._reject("slide", "a slide is a closed loop: not in dry run")
        if self._task is not None:
            return self._reject("slide", f"busy with {self._task.kind}")
        if self.estop.engaged:
            return self._reject("slide", "e-stop engaged")
        if self.q is None or self.watchdog_stale():
            return self._reject("slide", "no recent joint state", joint_states_lost=True)
        now = self.now_s()
        try:
            loop = SlideLoop(servo, direction_xyz, length_m, self.box.lower_xyz, self.box.upper_xyz, now,
                             planar=self.cfg.planar, max_contact_age_s=self.cfg.slide_max_contact_age_s,
                             normal_xyz=normal_xyz)
        except ValueError as exc:
            return self._reject("slide", str(exc))
        q = np.array(self.q, dtype=float)
        stub = TimedTrajectory(np.zeros(1), q[None], np.zeros((1, self.model.nq)), self.tip_xyz[None])
        self._slide = loop
        self._task = _Task("slide", stub, now)
        # The loop runs on the node clock (simulated time on the rig), one tick per servo period.
        self._slide_timer = self.node.create_timer(loop.period_s, self._slide_tick)
        return True

    def _slide_tick(self) -> None:
        """One servo tick (module docstring): the next target as a short replacing trajectory."""
        loop, task = self._slide, self._task
        if loop is None or task is None or task.kind != "slide":
            return
        self._flush_slide_contacts()
        now = self.now_s()
        if self._slide_stopping is not None:  # the servo stopped: the arm comes to rest, then the slide ends
            until_s, reason = self._slide_stopping
            if now >= until_s - 1e-9:
                self._end_slide(TaskResult.SUCCEEDED, reason)
            return
        if not loop.due(now) or self.q is None:
            return
        step = loop.tick(now, self.tip_xyz)
        if step.stop is not None:
            reason = f"slide stopped: {step.stop.value}, {loop.slid_m:.3f} m"
            # a jammed finger (force above the band) stops at once; otherwise the arm slows to rest
            stop = None if step.stop is SlideStop.FORCE else \
                stopping_trajectory(self.model, self.limits, self.box, self.q, self.qd)
            if stop is None:  # at rest already, jammed, or no room to slow down: stop here
                return self._end_slide(TaskResult.SUCCEEDED, reason)
            self._send_servo(task, stop)
            self._slide_stopping = (now + stop.duration_s, reason)
            return
        if step.target_xyz is not None:
            try:
                traj = tick_trajectory(self.model, self.limits, self.box, self.ik, self.q, self.qd, loop, step,
                                       self.cfg.slide_stream, self.cfg.max_joint_step_rad)
            except (OutsideWorkspace, TrajectoryError) as exc:
                loop.abort()
                return self._end_slide(TaskResult.ABORTED, f"servo step: {exc}")
            self._send_servo(task, traj)

    def _send_servo(self, task: _Task, traj: TimedTrajectory) -> None:
        msg = arm_msgs.trajectory_msg(traj, self.model.joint_names, topics.WORLD_FRAME)
        self._pub_planned.publish(msg)
        self._pub_traj.publish(msg)  # stamp 0: replaces the running one on receipt
        task.traj = traj

    def _flush_slide_contacts(self) -> None:
        if self._slide is not None:
            for frame in self._slide.take_published():
                self._hand_out(frame)

    def _hand_out(self, frame: FrameContact) -> None:
        """Publish one contact of the stream (through ``on_slide_contact``); its echo on
        /tactile/contacts is then not counted as the driver's."""
        self._own_contact_ns.add(int(round(frame.stamp_s * 1e9)))
        if self.on_slide_contact is not None:
            self.on_slide_contact(frame)

    def _end_slide(self, result: TaskResult, reason: str) -> None:
        self._halt(result, reason)  # hold where it is (the last step may still be running: stop it)

    def _close_slide(self, task: _Task) -> None:
        """The slide task ends (any reason): stop its timer, close and hand out its stream."""
        loop, self._slide = self._slide, None
        self._slide_stopping = None
        if self._slide_timer is not None:
            self.node.destroy_timer(self._slide_timer)
            self._slide_timer = None
        if loop is None:
            return
        loop.abort()
        for frame in loop.finish():
            self._hand_out(frame)
        stop = loop.stop or loop.servo.stopped
        task.extra.update(stop=stop.value if stop is not None else "aborted", slid_m=loop.slid_m,
                          contacts=loop.n_contacts, last_contact=loop.last_contact,
                          tip_path=np.array(loop.tip_path).reshape(-1, 3), ticks=loop.servo.ticks)

    def _path_point_before(self, contact_stamp_ns: Optional[int], clearance_m: float) -> Optional[np.ndarray]:
        """Joints of the last path waypoint ≥ ``clearance_m`` of tip travel before the contact, or None."""
        task = self._last
        if contact_stamp_ns is None or task is None or task.kind != "follow_path":
            return None
        return path_point_before(task.traj, task.start_s, contact_stamp_ns * 1e-9, clearance_m)

    def stop(self) -> None:
        """Stop now and hold (empty trajectory); the current task ends CANCELED."""
        self._halt(TaskResult.CANCELED, "stop requested")

    def sensor_silent_s(self, since_s: float = -np.inf) -> float:
        """How long (node clock) the driver has judged no frame, counted from ``since_s`` at the earliest
        (0 when it has judged frames up to now; inf before its first word)."""
        return max(0.0, self.now_s() - max(self.sensor_decided_s, since_s))

    def watchdog_stale(self) -> bool:
        """No joint state within ``watchdog_timeout_s`` (never in a dry run): a move would be rejected."""
        return not self.cfg.dry_run and self.watchdog.is_stale(self._steady_s())

    def is_task_complete(self) -> bool:
        return self._task is None

    def get_result(self) -> TaskResult:
        return self._last.result if self._last is not None else TaskResult.UNKNOWN

    @property
    def last_task(self) -> Optional[_Task]:
        """The finished task: result, reason, contact record and its stamp, trajectory."""
        return self._last

    def wait_until_complete(self, timeout_s: float) -> TaskResult:
        """Spin the node until the task ends or ``timeout_s`` (wall) passes (then stop: ABORTED)."""
        import rclpy

        deadline = self._steady.now().nanoseconds * 1e-9 + timeout_s
        while self._task is not None and self._steady.now().nanoseconds * 1e-9 < deadline:
            rclpy.spin_once(self.node, timeout_sec=self.cfg.control_period_s)
        if self._task is not None:
            self._halt(TaskResult.ABORTED, f"no result within {timeout_s:.1f} s")
        return self.get_result()

    def plan(self, path_xyz: np.ndarray, q_start: Optional[np.ndarray] = None, speed_mps: Optional[float] = None,
             step_m: Optional[float] = None, axes_xyz: Optional[np.ndarray] = None) -> TimedTrajectory:
        """Check the box and plan a trajectory (no motion; ``axes_xyz``: :meth:`ArmMotions.tip_path`).
        Raises OutsideWorkspace / TrajectoryError."""
        q0 = self._plan_start()[0] if q_start is None else np.asarray(q_start, dtype=float)
        return self.motions.tip_path(path_xyz, q0, speed_mps, step_m, axes_xyz=axes_xyz)

    def retrace(self, traj: TimedTrajectory, to_index: int) -> bool:
        """Back through the waypoints of a planned ``traj`` (joint space, in reverse) from where the arm is
        to waypoint ``to_index``, at tip speed (:meth:`ArmMotions.retrace`): a tilted finger's way back."""
        try:
            back = self.motions.retrace(traj, self._plan_start()[0], to_index)
        except (OutsideWorkspace, TrajectoryError) as exc:
            return self._reject("retrace", str(exc))
        return self._start("retrace", None, self.cfg.tip_speed_mps, self.cfg.waypoint_step_m, traj=back)

    def finger_tilt_rad(self) -> float:
        """The finger's angle from vertical (rad) at the joints the next plan starts from."""
        return tilt_of(self.model.fk(self._plan_start()[0])[1])

    # -- internals ----------------------------------------------------------------
    def now_s(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def state_time_s(self) -> float:
        """The node-clock time the newest joint state read describes the arm at (its stamp).

        A process behind on its joint-state queue knows where the arm was, not where it is: a motion is
        judged late only by states stamped after its deadline (ros2_control's goal_time_tolerance is in
        controller time too). The clock's now if the stamps are not on the node clock (none yet, more
        than ``MAX_STATE_LAG_S`` behind, or ahead of it)."""
        now = self.now_s()
        return self.q_stamp_s if now - MAX_STATE_LAG_S <= self.q_stamp_s <= now else now

    def _plan_start(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint vector and tip to plan from: measured, or (dry run without state) the last plan's end / home."""
        if self.cfg.dry_run and self._dry_q is not None:
            q = self._dry_q
        else:
            q = self.q if self.q is not None else self.home
        return q, self.model.fk(q)[0]

    def _reject(self, kind: str, reason: str, joint_states_lost: bool = False) -> bool:
        self.counters["rejected"] += 1
        self.log.warning(f"{kind} rejected: {reason}")
        self._last = _Task(kind, TimedTrajectory(np.zeros(1), np.zeros((1, self.model.nq)), np.zeros((1, self.model.nq)),
                                                 np.zeros((1, 3))), self.now_s(), result=TaskResult.REJECTED, reason=reason,
                           joint_states_lost=joint_states_lost)
        return False

    def _start(self, kind: str, path_xyz: Optional[np.ndarray], speed_mps: float, step_m: float,
               traj: Optional[TimedTrajectory] = None, q_start: Optional[np.ndarray] = None) -> bool:
        """Send ``traj``, or the plan of ``path_xyz`` from ``q_start`` (default: :meth:`_plan_start`),
        unless busy, e-stopped or without a recent joint state (then rejected, like a failed plan)."""
        if self._task is not None:
            return self._reject(kind, f"busy with {self._task.kind}")
        if self.estop.engaged:
            return self._reject(kind, "e-stop engaged")
        if (self.q is None and not self.cfg.dry_run) or self.watchdog_stale():
            return self._reject(kind, "no recent joint state", joint_states_lost=True)
        try:
            traj = traj if traj is not None else self.plan(path_xyz, q_start=q_start, speed_mps=speed_mps,
                                                           step_m=step_m)
        except (OutsideWorkspace, TrajectoryError) as exc:
            return self._reject(kind, str(exc))
        msg = arm_msgs.trajectory_msg(traj, self.model.joint_names, topics.WORLD_FRAME)
        now_ns = self.node.get_clock().now().nanoseconds
        start_ns = self._start_time_ns(now_ns)
        msg.header.stamp = time_from_ns(start_ns or now_ns)
        self._pub_planned.publish(msg)
        task = _Task(kind, traj, (start_ns or now_ns) * 1e-9)
        if self.cfg.dry_run:
            self._dry_q = traj.positions_rad[-1]
            task.result, task.reason = TaskResult.SUCCEEDED, "dry run: planned, not sent"
            self._last = task
            return True
        if not start_ns:
            msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0  # ros2_control: start now
        self._pub_traj.publish(msg)
        self._task = task
        return True

    def _start_time_ns(self, now_ns: int) -> int:
        """The start time of a trajectory sent now (0: on receipt; :func:`timed_start_ns`)."""
        return timed_start_ns(now_ns, self.cfg.start_lead_s, self.cfg.start_grid_s)

    def _halt(self, result: TaskResult, reason: str) -> None:
        """Send the stop (empty trajectory: hold position) and end the task."""
        if not self.cfg.dry_run:
            self._pub_traj.publish(arm_msgs.trajectory_msg(None, self.model.joint_names))
            self.counters["stops"] += 1
        self._finish(result, reason)

    def _finish(self, result: TaskResult, reason: str) -> None:
        if self._task is None:
            return
        # Robot time: from the motion's start to its end (or the stop), not the wait before a timed start.
        t = self._task
        if t.kind == "slide":  # a closed loop: its whole time is motion
            self._close_slide(t)
            self.motion_time_s += max(0.0, self.now_s() - t.start_s)
        else:
            self.motion_time_s += max(0.0, min(self.now_s(), t.start_s + t.traj.duration_s) - t.start_s)
        self._task.result, self._task.reason = result, reason
        self._last, self._task = self._task, None
        text = f"{self._last.kind}: {result.name.lower()} ({reason})"
        if result in (TaskResult.SUCCEEDED, TaskResult.CONTACT):  # rclpy: one severity per call site
            self.log.info(text)
        else:
            self.log.warning(text)

    def _steady_s(self) -> float:
        return self._steady.now().nanoseconds * 1e-9

    # -- callbacks ----------------------------------------------------------------
    def _on_joint_state(self, msg: JointState) -> None:
        q = arm_msgs.joint_positions(msg, self.model.joint_names)
        if q is None:
            self.counters["invalid_joint_states"] += 1
            self.log.warning(f"joint state without finite positions for {list(self.model.joint_names)}; ignored",
                             throttle_duration_sec=5.0)
            return
        self.watchdog.feed(self._steady_s())
        self.q_stamp_s = stamp_s(msg.header.stamp)
        self.qd = arm_msgs.joint_velocities(msg, self.model.joint_names)
        task = self._task
        if (task is not None and "arrived_s" not in task.extra and self.cfg.start_lead_s > 0
                and np.max(np.abs(q - task.traj.positions_rad[-1])) <= 1e-9):
            task.extra["arrived_s"] = self.q_stamp_s  # the first state at the end of the motion
        p, R = self.model.fk(q)
        if self.tip_xyz is not None:
            self.odometer_m += float(np.linalg.norm(p - self.tip_xyz))
        self.q, self.tip_xyz = q, p
        if self._pub_pose is not None and self.node.context.ok():  # not while shutting down
            self._pub_pose.publish(arm_msgs.pose_stamped(p, R, topics.WORLD_FRAME, msg.header.stamp))
        if self._on_state is not None:
            self._on_state(q, p, msg.header.stamp)

    def _contact_points(self, msg: PointCloud2, what: str) -> Optional[np.ndarray]:
        """The label-1 points of a contact cloud (None, counted and logged, if it does not decode)."""
        try:
            points = from_pointcloud2(msg, list(fields.CONTACT_DTYPE.names))
        except PointCloudError as exc:
            self.counters["invalid_contacts"] += 1
            self.log.warning(f"invalid {what} ignored: {exc}", throttle_duration_sec=5.0)
            return None
        return points[points["label"] == fields.LABEL_CONTACT]

    def _on_contacts(self, msg: PointCloud2) -> None:
        self._act_on_contacts(msg)
        self._publish_acted()

    def _act_on_contacts(self, msg: PointCloud2) -> None:
        hits = self._contact_points(msg, "contact cloud")
        if hits is None:
            return
        if len(hits) and (msg.header.frame_id != topics.WORLD_FRAME or not np.all(np.isfinite(fields.xyz(hits)))):
            # A contact that is not a place in the world cannot stop an approach (the touch would end
            # without an observation); the driver never sends one.
            self.counters["invalid_contacts"] += 1
            self.log.warning(f"contact ignored: frame '{msg.header.frame_id}' or a non-finite point",
                             throttle_duration_sec=5.0)
            return
        stamp_ns = arm_msgs.stamp_ns(msg.header.stamp)
        if len(hits) and stamp_ns in self._own_contact_ns:
            self._own_contact_ns.discard(stamp_ns)
            return  # our own slide stream, heard back
        if len(hits):
            self.contacts_received += 1
        task = self._task
        if task is None or task.kind in ("retract", "back_off", "slide"):  # off the surface, or meant to touch
            return
        if not len(hits) or stamp_ns * 1e-9 < task.start_s - 1e-3:
            return
        task.contact, task.contact_stamp_ns = hits[0], stamp_ns
        where = np.round(fields.xyz(hits[:1])[0], 4).tolist()
        if task.kind == "approach":
            self._halt(TaskResult.CONTACT, f"contact at {where}")
        else:  # a free-space path must not touch anything: the map was wrong, stop
            self._halt(TaskResult.ABORTED, f"unexpected contact at {where}")

    def _on_contact_frame(self, msg: PointCloud2) -> None:
        """The driver's per-frame contact stream (an empty cloud: released); used while sliding."""
        if self._slide is None:
            return
        hits = self._contact_points(msg, "contact frame")
        if hits is None:
            return
        t = arm_msgs.stamp_ns(msg.header.stamp) * 1e-9
        if not len(hits):
            return self._slide.on_frame(FrameContact(t, None))
        point, normal = fields.xyz(hits[:1])[0], fields.normals(hits[:1])[0]
        if msg.header.frame_id != topics.WORLD_FRAME or not np.all(np.isfinite(point)):
            self.counters["invalid_contacts"] += 1
            self.log.warning(f"contact frame ignored: frame '{msg.header.frame_id}' or a non-finite point",
                             throttle_duration_sec=5.0)
            return
        self._slide.on_frame(FrameContact(t, ContactSense(point, normal, float(hits["force"][0]))))

    def _on_sensor_decided(self, msg: DiagnosticStatus) -> None:
        values = {kv.key: kv.value for kv in msg.values}
        try:
            decided_s, sent = int(values["decided_through_ns"]) * 1e-9, int(values["contacts_sent"])
        except (KeyError, ValueError):
            self.counters["invalid_sensor_progress"] = self.counters.get("invalid_sensor_progress", 0) + 1
            return
        if decided_s >= self.sensor_decided_s:
            self.sensor_decided_s, self.sensor_contacts_sent = decided_s, sent
        self._publish_acted()

    def _publish_acted(self) -> None:
        """Lock-step with the simulated rig: once every contact the driver sent with its frames judged
        through ``sensor_decided_s`` is here (and a stop it called for published), say so on
        /arm/acted_through. The rig's clock waits for it, so a stop lands within a few ticks of the
        contact's frame however late this process runs (a real rig does not listen)."""
        t = self.sensor_decided_s
        if self.contacts_received < self.sensor_contacts_sent or not t > self.acted_through_s:
            return
        self.acted_through_s = t
        if self.node.context.ok():  # not while shutting down
            self._pub_acted.publish(DiagnosticStatus(
                name="arm_commander", message="acted", hardware_id="arm_commander",
                values=[KeyValue(key="acted_through_ns", value=str(ns_from_s(t)))]))

    def _on_estop(self, msg: Bool) -> None:
        if self.estop.set(msg.data):
            self.log.error("e-stop engaged: stopping")
        if self.estop.engaged:
            if self._task is not None:
                self._halt(TaskResult.ABORTED, "e-stop")
            elif not self.cfg.dry_run:
                self._pub_traj.publish(arm_msgs.trajectory_msg(None, self.model.joint_names))
        else:
            self.log.info("e-stop released")

    def _update(self) -> None:
        """Control tick (steady clock): watchdog, completion, time-outs."""
        now = self._steady_s()
        gap_s, self._last_tick_s = now - self._last_tick_s, now
        task = self._task
        if task is None:
            return
        # If this process itself was stalled (the tick is late), joint states may be waiting in
        # the queue: judge staleness on the next tick, after the executor has delivered them.
        if self.watchdog.is_stale(now) and gap_s < 0.5 * self.watchdog.timeout_s:
            task.joint_states_lost = True
            self._halt(TaskResult.ABORTED, f"joint states stale for {self.watchdog.age_s(now):.2f} s")
            return
        if (task.kind == "approach" and self.cfg.sensor_silence_s > 0 and np.isfinite(self.sensor_decided_s)
                and self.now_s() < task.start_s + task.traj.duration_s
                and self.sensor_silent_s(task.start_s) > self.cfg.sensor_silence_s):
            task.sensor_lost = True
            self.counters["sensor_silence_stops"] = self.counters.get("sensor_silence_stops", 0) + 1
            self._halt(TaskResult.ABORTED, f"the sensor driver judged no frame for "
                       f"{self.sensor_silent_s(task.start_s):.2f} s: stopped (a blind approach)")
            return
        if task.kind == "slide":
            return  # ended by its own loop (_slide_tick), the e-stop or the watchdog above
        elapsed = self.now_s() - task.start_s
        if elapsed < task.traj.duration_s:
            return
        err = float(np.max(np.abs(self.q - task.traj.positions_rad[-1])))
        end_s = task.start_s + task.traj.duration_s
        late = self.state_time_s() - task.start_s > task.traj.duration_s + self.cfg.goal_time_tolerance_s
        if self.cfg.start_lead_s > 0:
            # Timed starts (simulation): the motion is over when the arm is exactly at its end (the
            # controller may have started it late); the next one is then planned from those joints.
            if err > 1e-9:
                if late:
                    self._halt(TaskResult.ABORTED, f"goal not reached: joint error {err:.3f} rad")
                return
            end_s = task.extra.get("arrived_s", self.q_stamp_s)
        if task.kind in ("approach", "follow_path") and np.isfinite(self.sensor_decided_s):
            # Free space only once the driver has judged every frame up to the end of the motion (its
            # contact, if any, is then already here: a path that met the object ends as a contact however
            # late the message is); a driver that falls silent aborts it. For an approach, the frames of
            # contact_latency_s at rest at full depth count too (a contact sensed there is a contact): a
            # fixed window in the rig's time, so the outcome never depends on how late we look.
            settled_s = end_s + (self.cfg.contact_latency_s if task.kind == "approach" else 0.0)
            if self.sensor_decided_s < settled_s or self.contacts_received < self.sensor_contacts_sent:
                if elapsed > task.traj.duration_s + self.cfg.contact_latency_s + self.cfg.sensor_confirm_timeout_s:
                    self._halt(TaskResult.ABORTED, "the sensor driver did not confirm the end of the approach")
                return
        elif task.kind == "approach" and elapsed < task.traj.duration_s + self.cfg.contact_latency_s:
            return  # no word from the driver (a rig without it): wait a fixed latency for a late contact
        if err <= self.cfg.goal_tolerance_rad:
            self._finish(TaskResult.SUCCEEDED, f"{task.traj.length_m:.3f} m in {elapsed:.2f} s")
        elif late:
            self._halt(TaskResult.ABORTED, f"goal not reached: joint error {err:.3f} rad")
