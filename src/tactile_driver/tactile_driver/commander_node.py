"""Node ``arm_commander``: executes touches (goal + path) on the arm through ros2_control's topics.

In:  /planner/goal (PoseStamped), /planner/path (Path, same stamp as its goal; a slide goal's
     path ends with the slide marker, tactile_common.slide_goal),
     /joint_states, /tactile/contacts, /tactile/contact_frames (while sliding), /arm/estop (latched Bool).
Out: /joint_trajectory_controller/joint_trajectory (JointTrajectory; while sliding one short
     replacing trajectory per servo tick), ~/planned_trajectory (every planned trajectory, also in dry run),
     /arm/fingertip_pose, /tactile/contacts (the free-space point, label 0; a slide's thinned contact
     stream, label 1), /arm/touch_done (DiagnosticStatus). See docs/arm.md.
"""

from __future__ import annotations

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from tactile_common import fields, qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.cycle import TouchReport
from tactile_common.cycle_msgs import report_msg
from tactile_common.finger_axis import tilted_tail
from tactile_common.slide_goal import decode_path
from tactile_common.pointcloud import to_pointcloud2
from tactile_common.stamps import stamp_ns, time_from_ns
from tactile_common.touch_geometry import TouchGeometry
from tactile_driver import arm_msgs
from tactile_driver.commander_api import ArmCommander, CommanderConfig
from tactile_driver.goal_inbox import GoalInbox, Verdict
from tactile_driver.kinematics import KinematicsError
from tactile_driver.slide_loop import FrameContact
from tactile_driver.slide_servo import SlideServoConfig
from tactile_driver.startup_move import StartupMove
from tactile_driver.touch_executor import OUTCOME_UNREACHABLE, TouchExecutor, TouchRequest

_D = CommanderConfig()
START_ATTEMPTS = 3  # moves to the start position that may end for stalled joint states
_S = SlideServoConfig()
#: The slide servo's parameters (tactile_driver.slide_servo; the offline loop reads the same keys).
SLIDE_PARAMS = {
    "slide.slide_speed_mps": (_S.slide_speed_mps, "slide: tip speed along the surface (the servo's step = speed / "
                              "rate); keep equal to the planner's slide_speed_mps", {"gt": 0.0}),
    "slide.control_rate_hz": (_S.control_rate_hz, "slide: servo ticks per second (node clock), one replacing "
                              "trajectory each", {"gt": 0.0}),
    "slide.target_force_n": (_S.target_force_n, "slide: normal force the servo holds", {"gt": 0.0}),
    "slide.min_force_n": (_S.min_force_n, "slide: below this the contact is weak (no tangent step)", {"ge": 0.0}),
    "slide.max_force_n": (_S.max_force_n, "slide: above this the slide stops (jammed)", {"gt": 0.0}),
    "slide.gain_m_per_n": (_S.gain_m_per_n, "slide: normal correction per newton of force error", {"gt": 0.0}),
    "slide.max_correction_m": (_S.max_correction_m, "slide: largest normal correction per tick", {"gt": 0.0}),
    "slide.lost_ticks": (_S.lost_ticks, "slide: weak or lost this many ticks in a row: stop (an edge)", {"ge": 1}),
    "slide.thin_distance_m": (_S.thin_distance_m, "slide: publish a contact every this much contact travel",
                              {"gt": 0.0}),
    "slide.thin_angle_rad": (_S.thin_angle_rad, "slide: ...or when the normal turned by this much", {"gt": 0.0}),
    "slide.lap_radius_m": (_S.lap_radius_m,
                           "slide: contact and tip back within this of the first contact's, or the tip "
                           "of its own path: a lap, stop (0 = off)",
                           {"ge": 0.0}),
    "slide.approach_depth_m": (_S.approach_depth_m, "slide: the guarded approach's depth beyond the estimated "
                               "surface before a slide", {"gt": 0.0}),
    "slide.max_contact_age_s": (0.25, "slide: a contact frame older than this (node clock) is no contact "
                                "(a silent driver stops the slide)", {"gt": 0.0}),
    "slide.stream": (True, "slide: velocity-continuous servo steps (each tick's trajectory reaches its target "
                     "moving at the slide speed, then a stopping tail; the next tick replaces it), so the "
                     "finger slides at slide_speed_mps; false: rest-ended steps (slower, docs/arm.md)"),
}
PARAMS = {
    "urdf_path": (_D.urdf_path, "URDF of the arm; '' = Franka Panda from example-robot-data"),
    "joint_names": (list(_D.joint_names), "actuated joints, in command order"),
    "flange_frame": (_D.flange_frame, "URDF frame the finger is mounted on"),
    "tip_offset_m": (_D.tip_offset_m, "tip centre along the flange z-axis", {"ge": 0.0}),
    "home_rad": (list(_D.home_rad), "home joints (planning start in dry run without joint states)"),
    "box_x_m": (list(_D.box_x_m), "safety box of the tip centre, world x [min, max]", {"length": 2, "increasing": True}),
    "box_y_m": (list(_D.box_y_m), "safety box y [min, max]", {"length": 2, "increasing": True}),
    "box_z_m": (list(_D.box_z_m), "safety box z [min, max]", {"length": 2, "increasing": True}),
    "table_z_m": (_D.table_z_m, "table top height"),
    "table_margin_m": (_D.table_margin_m, "tip centre stays above table + margin + tip radius", {"ge": 0.0}),
    "tip_radius_m": (_D.tip_radius_m, "fingertip radius", {"gt": 0.0}),
    "tip_speed_mps": (_D.tip_speed_mps, "max tip speed along the free-space path", {"gt": 0.0}),
    "approach_speed_mps": (_D.approach_speed_mps, "tip speed of the guarded approach and the retract", {"gt": 0.0}),
    "standoff_m": (0.01, "pre-touch standoff from the candidate surface (the planner's value)", {"gt": 0.0}),
    "max_depth_m": (0.02, "how far the finger's skin may go beyond the estimated surface point before the "
                    "approach counts as free space (tactile_common.touch_geometry)", {"gt": 0.0}),
    "dwell_s": (0.5, "pause at the end of the approach", {"ge": 0.0}),
    "max_joint_velocity_rad_s": (list(_D.max_joint_velocity_rad_s), "per-joint speed cap (URDF limit if lower)", {"gt": 0.0}),
    "max_joint_acceleration_rad_s2": (list(_D.max_joint_acceleration_rad_s2), "per-joint acceleration cap", {"gt": 0.0}),
    "waypoint_step_m": (_D.waypoint_step_m, "max tip step between IK waypoints on the path", {"gt": 0.0}),
    "approach_step_m": (_D.approach_step_m, "max tip step between IK waypoints on approach/retract", {"gt": 0.0}),
    "max_joint_step_rad": (_D.max_joint_step_rad, "max joint change between waypoints (IK branch flip guard)", {"gt": 0.0}),
    "ik_tol_m": (_D.ik_tol_m, "IK position tolerance", {"gt": 0.0}),
    "max_tilt_rad": (_D.max_tilt_rad, "max finger tilt from vertical", {"ge": 0.0}),
    "wrist_bands_m": (list(_D.wrist_bands_m), "the links behind the flange as cylinders about the finger axis, "
                      "[t0, t1, radius, ...] (m behind the flange): no plan of a tilted finger takes them below "
                      "table + margin (tactile_common.wrist; default: the Panda's link 7 and link 6)"),
    "goal_tolerance_rad": (_D.goal_tolerance_rad, "joint error accepted at the end of a trajectory", {"gt": 0.0}),
    "goal_time_tolerance_s": (_D.goal_time_tolerance_s, "extra time to reach it before aborting", {"ge": 0.0}),
    "contact_latency_s": (_D.contact_latency_s, "an approach that reached full depth counts the frames of this "
                          "long at rest there (a contact then is a contact); without driver progress messages, "
                          "the time it waits for a late contact", {"ge": 0.0}),
    "start_lead_s": (_D.start_lead_s, "0: a trajectory starts when the controller receives it (ros2_control's "
                     "default); > 0: it starts this long after it is sent (header.stamp)", {"ge": 0.0}),
    "start_grid_s": (_D.start_grid_s, "with start_lead_s: start times on a multiple of this (the simulated rig's "
                     "tick), so the rig samples every motion identically (0 = no grid)", {"ge": 0.0}),
    "sensor_confirm_timeout_s": (_D.sensor_confirm_timeout_s, "an approach at full depth waits this long (node "
                                 "clock) for the driver to judge its last frames, then aborts", {"gt": 0.0}),
    "sensor_silence_s": (_D.sensor_silence_s, "an approach stops when the sensor driver has judged no frame for "
                         "this long (node clock), retracts once the driver is back and approaches again "
                         "(0 = off; a rig without the driver never stops for it)", {"ge": 0.0}),
    "watchdog_timeout_s": (_D.watchdog_timeout_s, "joint states older than this (steady clock) stop motion", {"gt": 0.0}),
    "control_period_s": (_D.control_period_s, "watchdog / completion check period (steady clock)", {"gt": 0.0}),
    "move_to_start": (True, "at start-up move the tip to start_tip_xyz_m (the explorer waits for it there)"),
    "start_tip_xyz_m": ([0.35, 0.0, 0.06], "start position of the tip (world); must equal the explorer's", {"length": 3}),
    "start_clearance_z_m": (0.25, "transfer height above the objects on the way to the start position"),
    "dry_run": (False, "plan and publish on ~/planned_trajectory only; send nothing to the controller"),
    "trajectory_topic": (_D.trajectory_topic, "ros2_control joint_trajectory_controller input"),
    "mode": ("2d", "'2d': slides stay in the x-y plane; '3d'", {"choices": ("2d", "3d")}),
    **SLIDE_PARAMS,
}


class ArmCommanderNode(Node):
    """Wiring: goal + path -> GoalInbox -> TouchExecutor (ArmCommander verbs) -> touch_done."""

    def __init__(self) -> None:
        super().__init__("arm_commander")
        started_ns = time.time_ns()  # wall clock, as the DDS source timestamps of the goals
        p = declare_parameters(self, PARAMS)
        cfg = CommanderConfig(**{k: v for k, v in vars(p).items() if k in CommanderConfig.__dataclass_fields__},
                              planar=p.mode == "2d")  # slide_max_contact_age_s: the slide. parameter
        values = vars(p)
        servo = SlideServoConfig.from_params({k: values[k.replace(".", "_")] for k in SLIDE_PARAMS}, "slide.")
        try:
            self.arm = ArmCommander(self, cfg)
        except KinematicsError as exc:
            raise ValueError(str(exc)) from None
        geometry = TouchGeometry(p.tip_radius_m, p.standoff_m, p.max_depth_m)
        self.touches = TouchExecutor(self.arm, geometry.approach_length_m, p.dwell_s,
                                     self._publish_free_space, self._publish_done,
                                     back_off_clearance_m=p.standoff_m, slide_servo=servo,
                                     slide_approach_length_m=p.standoff_m + servo.approach_depth_m,
                                     min_approach_m=geometry.min_approach_m)
        self.arm.on_slide_contact = self._publish_slide_contact
        self.inbox = GoalInbox(started_ns)
        self.startup = StartupMove(self.arm, p.start_tip_xyz_m, p.start_clearance_z_m, START_ATTEMPTS,
                                   self.get_logger()) if p.move_to_start else None
        self.touches.hold = p.move_to_start  # touches wait until the tip is at the start position
        self.invalid_goals = 0
        self._pub_contacts = self.create_publisher(PointCloud2, topics.CONTACTS, qos.OBSERVATIONS)
        self._pub_done = self.create_publisher(DiagnosticStatus, topics.TOUCH_DONE, qos.EVENTS)
        self.create_subscription(PoseStamped, topics.GOAL, self._on_goal, qos.EVENTS)
        self.create_subscription(Path, topics.PATH, self._on_path, qos.EVENTS)
        self.create_timer(cfg.control_period_s, self._tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f"arm_commander ready: {self.arm.model.nq} joints, tip {cfg.tip_offset_m} m from {cfg.flange_frame}, "
            f"box {self.arm.box.lower_xyz.tolist()} .. {self.arm.box.upper_xyz.tolist()}, dry_run={cfg.dry_run}"
        )

    def _tick(self) -> None:
        if self.startup is not None and not self.startup.done:
            self.startup.update()
            self.touches.hold = not self.startup.done  # queued touches go ahead, wherever the tip ended
        elif (orphan := self.inbox.orphan()) is not None:  # after a restart: the touch that was under way
            self._publish_done(orphan)
        self.touches.update()

    def _on_goal(self, msg: PoseStamped, info: dict) -> None:  # info: rclpy's message info (send time)
        sent_ns = int(info.get("source_timestamp") or time.time_ns())
        self._handle(self.inbox.add_goal(stamp_ns(msg.header.stamp), msg, sent_ns))

    def _on_path(self, msg: Path) -> None:
        self._handle(self.inbox.add_path(stamp_ns(msg.header.stamp), msg))

    def _handle(self, decision) -> None:
        if decision is None:
            return
        if decision.verdict is Verdict.RESEND_REPORT:
            self.get_logger().info(f"goal {decision.stamp_ns} again: {decision.reason}")
            self._pub_done.publish(report_msg(decision.report))
            return
        if decision.verdict is Verdict.IGNORE:
            self.get_logger().info(f"goal {decision.stamp_ns} ignored: {decision.reason}")
            return
        try:
            position, rotation = arm_msgs.pose_arrays(decision.goal.pose)
            plan = decode_path(arm_msgs.path_xyz(decision.path), position)  # a slide: its marker split off
            path_xyz = plan.free_path_xyz
            if not (np.all(np.isfinite(position)) and np.all(np.isfinite(path_xyz))):
                raise ValueError("goal or path is not finite")
            axes = arm_msgs.path_axes(decision.path)[: len(path_xyz)]  # the finger axis at each pose
            tail = tilted_tail(np.vstack([path_xyz, position[None]]), np.vstack([axes, axes[-1:]]),
                               self.arm.cfg.max_tilt_rad) if len(axes) else None
            if tail is not None and plan.is_slide:
                raise ValueError("a slide with a tilted finger: slides keep the finger vertical")
            frames = {decision.goal.header.frame_id, decision.path.header.frame_id}
            frames |= {ps.header.frame_id for ps in decision.path.poses if ps.header.frame_id}
            if frames != {topics.WORLD_FRAME}:
                raise ValueError(f"goal or path in frame(s) {sorted(frames)}, expected '{topics.WORLD_FRAME}'")
        except ValueError as exc:
            self.invalid_goals += 1
            self.get_logger().error(f"invalid goal {decision.stamp_ns}: {exc}")
            return self._publish_done(TouchReport(decision.stamp_ns, OUTCOME_UNREACHABLE, str(exc), None, 0.0, 0.0))
        self.touches.submit(TouchRequest(decision.stamp_ns, position, rotation[:, 0], path_xyz,
                                         plan.slide_direction_xyz, plan.slide_length_m,
                                         axes if tail is not None else None, tail))

    def _publish_free_space(self, tip_xyz: np.ndarray, observation_stamp_ns: int, sweep_xyz: np.ndarray) -> None:
        """The probe end (label 0); its normal fields hold the sweep vector back to the approach's start."""
        point = np.zeros(1, dtype=fields.CONTACT_DTYPE)
        point["x"], point["y"], point["z"] = tip_xyz
        point["normal_x"], point["normal_y"], point["normal_z"] = sweep_xyz
        point["label"] = fields.LABEL_FREE_SPACE
        self._pub_contacts.publish(to_pointcloud2(point, topics.WORLD_FRAME, time_from_ns(observation_stamp_ns)))

    def _publish_slide_contact(self, frame: FrameContact) -> None:
        """One contact of a slide's thinned stream (label 1, stamp = its frame's)."""
        point = np.zeros(1, dtype=fields.CONTACT_DTYPE)
        point["x"], point["y"], point["z"] = frame.sense.point_xyz
        point["normal_x"], point["normal_y"], point["normal_z"] = frame.sense.normal_xyz
        point["force"], point["label"] = frame.sense.force_n, fields.LABEL_CONTACT
        self._pub_contacts.publish(to_pointcloud2(point, topics.WORLD_FRAME, time_from_ns(
            int(round(frame.stamp_s * 1e9)))))

    def _publish_done(self, report: TouchReport) -> None:
        self.inbox.finished(report)
        self._pub_done.publish(report_msg(report))
        text = (f"touch {report.goal_stamp_ns}: {report.outcome.value} {report.reason} "
                f"(travel {report.travel_m:.3f} m, {report.duration_s:.2f} s)")
        if report.outcome.observed:  # rclpy: one severity per call site
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)


def main(args=None) -> int:
    return run_node(ArmCommanderNode, args)
