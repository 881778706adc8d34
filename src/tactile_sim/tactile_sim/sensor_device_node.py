"""Node ``sim_sensor_device``: the simulated tactile sensor alone (no arm), for tests and bench setups.

Holds a hidden object (``tactile_sim.objects.make_object``) and serves a
:class:`tactile_sim.sensor_device.SimulatedSensorDevice` on the pty behind
``link_path``. Each pose on /arm/fingertip_pose moves the fingertip and
writes the frames due up to the pose's stamp, so every frame shows the world
at its own time even when poses arrive late. Without poses for
``pose_timeout_s``, a timer on the node clock (simulated time with
``use_sim_time``) keeps the device streaming at the last pose.

The timeout is long (1 s) on purpose: rclpy's executor runs a due timer
before the subscriptions that are ready, so after this process was starved
the timer would write the frames of the starved interval at the old pose
before the queued poses are read. Those frames show the finger where it no
longer was: with a 0.1 s timeout, a contact came out 3-6 mm deep whenever
the process stalled for longer during an approach (two CI failures).

Health on /diagnostics (status ``sim_sensor_device``, every
``diagnostics_period_s`` wall): poses received and how late the last one
came (node clock minus its stamp), frames sent and lost. Until the first pose
arrives the frames show the tip far from everything: a test or bench script
waits for ``poses`` > 0 before it moves the tip (the publisher's subscription
count alone does not say the device hears it: discovery matches the two ends
at different times, and the backlog then arrives late).
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from tactile_common import qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.rotations import quaternion_to_matrix, xyzw
from tactile_common.stamps import stamp_s
from tactile_driver.taxels import load_layout, resolve_layout_file
from tactile_sim.device_params import DEVICE_PARAMETERS, OBJECT_PARAMETERS
from tactile_sim.objects import make_object
from tactile_sim.sensor_device import FaultConfig, SimulatedSensorDevice
from tactile_sim.sensor_model import SensorModelConfig

PARAMS = {
    "link_path": ("/tmp/tactile_sim/sensor", "symlink to the pty the driver opens"),
    "layout_file": ("", "taxel layout YAML; '' = tactile_driver's taxels_ring.yaml (2d) / taxels_hemisphere.yaml (3d)"),
    "frame_rate_hz": (200.0, "frame rate in node-clock time", {"gt": 0.0}),
    "step_period_s": (0.005, "timer period that writes the due frames without poses (node clock)", {"gt": 0.0}),
    "pose_timeout_s": (1.0, "without a pose this long (s, node clock), the timer drives the device at the last pose; "
                       "longer than the stalls of a loaded machine (module docstring)", {"gt": 0.0}),
    "seed": (0, "seed of the noise, baselines and faults", {"ge": 0}),
    "diagnostics_period_s": (1.0, "period of the device's /diagnostics status (wall clock)", {"gt": 0.0}),
    **OBJECT_PARAMETERS,
    **DEVICE_PARAMETERS,
}


class SimSensorDeviceNode(Node):
    def __init__(self) -> None:
        super().__init__("sim_sensor_device")
        p = declare_parameters(self, PARAMS)
        obj = make_object(p.object, p.mode, tuple(p.object_xy_m), p.object_yaw_rad, p.object_scale, p.prism_height_m)
        layout = load_layout(resolve_layout_file(p.layout_file, p.mode))
        faults = FaultConfig(
            garbage_prob=p.fault_garbage_prob, crc_error_prob=p.fault_crc_error_prob, drop_prob=p.fault_drop_prob,
            stuck_taxel=p.fault_stuck_taxel, stuck_value=p.fault_stuck_value, stuck_after_s=p.fault_stuck_after_s,
            disconnect_at_s=p.fault_disconnect_at_s, disconnect_for_s=p.fault_disconnect_for_s)
        model = SensorModelConfig(stiffness_pa_per_m=p.model_stiffness_pa_per_m, spread_m=p.model_spread_m,
                                  counts_per_newton=p.model_counts_per_newton, noise_counts=p.model_noise_counts)
        self.device = SimulatedSensorDevice(obj, layout, p.link_path, p.frame_rate_hz, p.seed, faults, model)
        self.device.open()
        self.pose_timeout_s = p.pose_timeout_s
        self._last_pose_s = None
        self._poses = 0
        self._pose_lag_s = float("nan")  # node clock minus the stamp, when the last pose was read
        self.create_subscription(PoseStamped, topics.FINGERTIP_POSE, self._on_pose, qos.STATE)
        self.create_timer(p.step_period_s, self._step)
        self._pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_timer(p.diagnostics_period_s, self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"sim_sensor_device: object '{p.object}' ({p.mode}), {layout.n_taxels} taxels "
                               f"at {p.frame_rate_hz:g} Hz on {p.link_path}")

    def _on_pose(self, msg: PoseStamped) -> None:
        pp, q = msg.pose.position, msg.pose.orientation
        t_s = stamp_s(msg.header.stamp)
        try:
            self.device.set_pose([pp.x, pp.y, pp.z], quaternion_to_matrix(xyzw(q)))
        except ValueError as exc:
            self.get_logger().warn(f"ignored fingertip pose: {exc}", throttle_duration_sec=5.0)
            return
        self._last_pose_s = t_s
        self._poses += 1
        self._pose_lag_s = self.get_clock().now().nanoseconds * 1e-9 - t_s
        self.device.step(t_s)

    def _step(self) -> None:
        now_s = self.get_clock().now().nanoseconds * 1e-9
        if self._last_pose_s is None or now_s - self._last_pose_s > self.pose_timeout_s:
            self.device.step(now_s)

    def _publish_diagnostics(self) -> None:
        st = self.device.stats
        silent_s = self.get_clock().now().nanoseconds * 1e-9 - (self._last_pose_s or 0.0)
        if self._poses == 0:
            level, message = DiagnosticStatus.WARN, "no fingertip pose yet: the frames show the tip far away"
        elif silent_s > self.pose_timeout_s:
            level, message = DiagnosticStatus.WARN, f"no fingertip pose for {silent_s:.1f} s: streaming at the last one"
        elif self._pose_lag_s > self.pose_timeout_s:
            level, message = DiagnosticStatus.WARN, f"fingertip poses arrive {self._pose_lag_s:.2f} s late"
        else:
            level, message = DiagnosticStatus.OK, "following the fingertip pose"
        counts = {"poses": self._poses, "pose_lag_s": f"{self._pose_lag_s:.3f}", "frames_sent": st.frames_sent,
                  "frames_lost": st.frames_lost, "frames_dropped": st.frames_dropped,
                  "garbage_bytes": st.garbage_bytes, "crc_corrupted": st.crc_corrupted,
                  "disconnects": st.disconnects, "reconnects": st.reconnects}
        status = DiagnosticStatus(level=level, name="sim_sensor_device", message=message,
                                  hardware_id=str(self.device.link_path),
                                  values=[KeyValue(key=k, value=str(v)) for k, v in counts.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._pub_diag.publish(msg)

    def close(self) -> None:
        self.device.close()


def main(args=None) -> int:
    return run_node(SimSensorDeviceNode, args)
