"""Node ``sim_rig``: the simulated arm, clock, object and tactile sensor device.

Per tick of ``rate_hz`` simulated time (ticks run at ``real_time_factor`` ×
wall time, steady clock): advance /clock, sample the emulated
joint_trajectory_controller, publish /joint_states, put the fingertip at its
forward kinematics and let the simulated sensor device write the frames due
(on the pty behind ``sensor_link_path``). The arm is not stopped by the
object: the commander's guarded approach must stop it.

Lock-step (:mod:`tactile_sim.clock_gate`): simulated time waits for the
driver to read the frames sent and for the sensing loop (the driver's
/tactile/decided_through, the commander's /arm/acted_through) to keep up, so
on a loaded machine the simulation slows down instead of running ahead of the
sensing: an approach stops within a few ticks of its contact's frame however
late the commander runs, and a slide's servo sees contacts a few milliseconds
old, as on a real rig.
"""

from __future__ import annotations

import time

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from diagnostic_msgs.msg import DiagnosticStatus
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from tactile_common import qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.stamps import stamp_s, time_from_s
from tactile_driver.kinematics import PANDA_FLANGE, PANDA_JOINTS, ArmModel, KinematicsError, home_configuration
from tactile_sim.clock_gate import ClockGate
from tactile_sim.device_params import DEVICE_PARAMETERS, OBJECT_PARAMETERS
from tactile_sim.controller import TrajectoryController, TrajectoryRejected
from tactile_sim.sensor_device import motion_key

HOME_RAD = [0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854]  # Panda: tip at (0.50, 0.00, 0.35), finger vertical

PARAMS = {
    "urdf_path": ("", "URDF of the arm; '' = Franka Panda from example-robot-data"),
    "joint_names": (list(PANDA_JOINTS), "controlled joints"),
    "flange_frame": (PANDA_FLANGE, "URDF frame the finger is mounted on"),
    "tip_offset_m": (0.16, "tip centre along the flange z-axis", {"ge": 0.0}),
    "home_rad": (HOME_RAD, "initial joint positions"),
    "rate_hz": (100.0, "controller, /joint_states and /clock rate in simulated time", {"gt": 0.0}),
    "real_time_factor": (1.0, "simulated seconds per wall second", {"gt": 0.0}),
    "trajectory_topic": (topics.JOINT_TRAJECTORY, "joint_trajectory_controller input"),
    "sensor_enabled": (True, "serve the simulated tactile sensor on a pty"),
    "sensor_link_path": ("/tmp/tactile_sim/sensor", "symlink to the pty the driver opens"),
    "sensor_layout": ("", "taxel layout YAML; '' = tactile_driver's taxels_ring.yaml (2d) / taxels_hemisphere.yaml (3d)"),
    "sensor_frame_rate_hz": (200.0, "sensor frame rate (simulated time)", {"gt": 0.0}),
    "sensor_seed": (0, "seed of the sensor noise, baselines and faults", {"ge": 0}),
    "sensor_max_hold_s": (2.0, "lock-step: the clock waits for a driver that is behind reading frames, at most this "
                          "long in a row (wall clock); then frames are dropped", {"ge": 0.0}),
    "sensor_max_lag_s": (0.03, "lock-step: the clock waits while the driver's judged frames (decided_through), or "
                         "the frames whose contacts the commander acted on (acted_through), are more than this "
                         "behind simulated time (s; at most sensor_max_hold_s wall in a row; "
                         "0 = off)", {"ge": 0.0}),
    "sensor_max_lag_hold_s": (0.25, "lock-step: the longest wait for the sensing loop (wall clock); then one tick "
                              "goes through (keep it below the commander's watchdog_timeout_s)", {"gt": 0.0}),
    **OBJECT_PARAMETERS,
    **DEVICE_PARAMETERS,
}


class SimRig(Node):
    def __init__(self) -> None:
        super().__init__("sim_rig")
        p = declare_parameters(self, PARAMS)
        if p.rate_hz <= 0 or p.real_time_factor <= 0:
            raise ValueError("rate_hz and real_time_factor must be positive")
        try:
            self.model = ArmModel(p.urdf_path, p.joint_names, p.flange_frame, p.tip_offset_m)
        except KinematicsError as exc:
            raise ValueError(str(exc)) from None
        q0 = home_configuration(self.model, p.home_rad)
        self.controller = TrajectoryController(self.model.joint_names, q0)
        self.dt_s = 1.0 / p.rate_hz
        self.t_s = 0.0
        self.device = self._make_device(p) if p.sensor_enabled else None
        self.gate = ClockGate(p.sensor_max_hold_s, p.sensor_max_lag_s, p.sensor_max_lag_hold_s)
        self.late_starts = 0  # trajectories received after their start time
        self._pub_clock = self.create_publisher(ClockMsg, topics.CLOCK, qos.CLOCK)
        self._pub_js = self.create_publisher(JointState, topics.JOINT_STATES, qos.STATE)
        self.create_subscription(JointTrajectory, p.trajectory_topic, self._on_trajectory, qos.COMMANDS)
        if self.device is not None and self.gate.max_lag_s > 0:
            self.create_subscription(DiagnosticStatus, topics.SENSOR_DECIDED, self._on_decided, qos.SENSOR)
            self.create_subscription(DiagnosticStatus, topics.ARM_ACTED, self._on_acted, qos.SENSOR)
        # The rig is the clock source: it ticks on the steady clock, whatever use_sim_time says.
        self.create_timer(self.dt_s / p.real_time_factor, self._tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        tip = self.model.fk(q0)[0]
        self.get_logger().info(
            f"sim_rig: {p.rate_hz:.0f} Hz x{p.real_time_factor:g} real time, tip at {np.round(tip, 3).tolist()}, "
            f"object '{p.object}' ({p.mode}) at {list(p.object_xy_m)}"
            + (f", sensor on {p.sensor_link_path}" if self.device else ", no sensor")
        )

    def _make_device(self, p):
        from tactile_driver.taxels import load_layout, resolve_layout_file
        from tactile_sim.objects import make_object
        from tactile_sim.sensor_device import FaultConfig, SimulatedSensorDevice
        from tactile_sim.sensor_model import SensorModelConfig

        # The physical object is always a solid: in 2D mode the section becomes its prism
        # (the finger above the prism must not touch it).
        obj = make_object(p.object, "3d", tuple(p.object_xy_m), p.object_yaw_rad, p.object_scale, p.prism_height_m)
        layout = load_layout(resolve_layout_file(p.sensor_layout, p.mode))
        faults = FaultConfig(
            garbage_prob=p.fault_garbage_prob, crc_error_prob=p.fault_crc_error_prob, drop_prob=p.fault_drop_prob,
            stuck_taxel=p.fault_stuck_taxel, stuck_value=p.fault_stuck_value, stuck_after_s=p.fault_stuck_after_s,
            disconnect_at_s=p.fault_disconnect_at_s, disconnect_for_s=p.fault_disconnect_for_s)
        model = SensorModelConfig(stiffness_pa_per_m=p.model_stiffness_pa_per_m, spread_m=p.model_spread_m,
                                  counts_per_newton=p.model_counts_per_newton, noise_counts=p.model_noise_counts)
        device = SimulatedSensorDevice(obj, layout, p.sensor_link_path, p.sensor_frame_rate_hz, p.sensor_seed,
                                       faults, model)
        device.open()
        return device

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        times = np.array([stamp_s(pt.time_from_start) for pt in msg.points])
        start_s = stamp_s(msg.header.stamp)
        try:
            # A ragged message (points of different sizes) makes numpy raise ValueError.
            positions = (np.array([list(pt.positions) for pt in msg.points], dtype=float) if len(times)
                         else np.zeros((0, len(msg.joint_names))))
            has_vel = len(msg.points) > 0 and all(len(pt.velocities) for pt in msg.points)
            velocities = np.array([list(pt.velocities) for pt in msg.points], dtype=float) if has_vel else None
            self.controller.command(self.t_s, msg.joint_names, times, positions, velocities, start_s)
            if 0 < start_s < self.t_s - 1e-9 and len(times):
                self.late_starts += 1
                self.get_logger().warning(f"trajectory arrived {self.t_s - start_s:.3f} s after its start time "
                                          f"({self.late_starts} so far): started late (raise the commander's "
                                          f"start_lead_s)", throttle_duration_sec=5.0)
            if self.device is not None and len(times):  # the noise of this motion's frames: keyed on it
                self.device.begin_motion(motion_key(positions), self.t_s if start_s <= self.t_s else start_s)
        except (TrajectoryRejected, ValueError) as exc:
            self.get_logger().error(f"trajectory rejected ({self.controller.rejected} so far): {exc}")

    def _tick(self) -> None:
        if not self.context.ok():  # SIGINT arrived during this spin: publishing would raise
            return
        if self.device is not None and self.gate.hold(self.t_s, self.device.backlog_bytes, time.monotonic()):
            return  # lock-step: simulated time waits for the sensing loop (no frame is dropped for load)
        self.t_s += self.dt_s
        stamp = time_from_s(self.t_s)
        self._pub_clock.publish(ClockMsg(clock=stamp))
        q, qd = self.controller.state(self.t_s)
        js = JointState(name=list(self.model.joint_names), position=q.tolist(), velocity=qd.tolist())
        js.header.stamp = stamp
        self._pub_js.publish(js)
        if self.device is not None:
            self.device.set_pose(*self.model.fk(q))
            self.device.step(self.t_s)

    def _on_decided(self, msg: DiagnosticStatus) -> None:
        t = _progress_s(msg, "decided_through_ns")
        if t is not None:
            self.gate.on_decided(t)

    def _on_acted(self, msg: DiagnosticStatus) -> None:
        t = _progress_s(msg, "acted_through_ns")
        if t is not None:
            self.gate.on_acted(t)

    def close(self) -> None:
        if self.device is not None:
            self.device.close()


def _progress_s(msg: DiagnosticStatus, key: str) -> float | None:
    """The stamp (s) in a progress message's ``key`` (ns), None if it has none."""
    try:
        return int({kv.key: kv.value for kv in msg.values}[key]) * 1e-9
    except (KeyError, ValueError):
        return None


def main(args=None) -> int:
    return run_node(SimRig, args)
