"""Node ``tactile_sensor``: the tactile sensor driver.

Reads the serial device (``port``, ``baud``; reconnects with back-off), and
per frame publishes the raw taxels on /tactile/taxels and, at each contact
onset, one point on /tactile/contacts (world frame, CONTACT_DTYPE, label 1,
stamp = frame time) using the fingertip pose interpolated from
/arm/fingertip_pose. While in contact, every frame's estimate also goes to
/tactile/contact_frames (one point, same layout; an empty cloud at the frame
the contact is released): the per-frame input of a slide's servo (the arm
commander thins it into the /tactile/contacts stream). Health on /diagnostics. The work is done by
:class:`tactile_driver.driver.SensorDriver`; this file only wires it.
"""

from __future__ import annotations

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float32MultiArray, MultiArrayDimension

from tactile_common import fields, qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import to_pointcloud2
from tactile_common.rotations import xyzw
from tactile_common.stamps import ns_from_s, stamp_s, time_from_s
from tactile_driver.contact import ContactConfig
from tactile_driver.driver import DriverConfig, SensorDriver, WorldContact
from tactile_driver.serial_link import SerialLink
from tactile_driver.taxels import load_layout, resolve_layout_file

PARAMS = {
    "port": ("/tmp/tactile_sim/sensor", "serial device path of the sensor (a pty symlink in simulation)"),
    "baud": (921600, "serial baud rate", {"gt": 0}),
    "layout_file": ("taxels_ring.yaml", "taxel layout YAML: a path, or a file name in tactile_driver/config"),
    "world_frame": (topics.WORLD_FRAME, "frame of the published contacts"),
    "poll_period_s": (0.002, "serial read period (wall clock)", {"gt": 0.0}),
    "reconnect_min_s": (0.1, "first reconnect delay; doubles per failure", {"gt": 0.0}),
    "reconnect_max_s": (2.0, "largest reconnect delay", {"gt": 0.0}),
    "diagnostics_period_s": (1.0, "diagnostics period (wall clock)", {"gt": 0.0}),
    "max_frame_age_s": (0.25, "frames older than this when read are stale: never used", {"gt": 0.0}),
    "pose_tolerance_s": (0.02, "a frame may be this far outside the buffered poses", {"ge": 0.0}),
    "pose_buffer_s": (2.0, "length of the fingertip pose buffer", {"gt": 0.0}),
    "pose_wait_s": (0.2, "a contact newer than the newest pose waits this long for its pose", {"ge": 0.0}),
    "clock_window_s": (2.0, "window of the device-clock offset estimate", {"gt": 0.0}),
    "device_clock_is_ros_time": (False, "the device stamps frames in ROS time (the simulated device: sim "
                                        "time); else the offset is estimated from arrival times"),
    "contact.counts_per_newton": (10000.0, "taxel counts per newton of force", {"gt": 0.0}),
    "contact.on_threshold_n": (0.05, "contact on at this force", {"gt": 0.0}),
    "contact.off_threshold_n": (0.025, "contact off below this force", {"ge": 0.0}),
    "contact.noise_gate_sigma": (4.0, "a taxel is active above this many noise std", {"ge": 0.0}),
    "contact.min_noise_counts": (1.0, "floor of a taxel's noise std", {"gt": 0.0}),
    "contact.min_active_taxels": (2, "active taxels needed for a contact", {"ge": 1}),
    "contact.calibration_frames": (40, "frames of the start-up baseline (no contact!)", {"ge": 1}),
    "contact.stuck_frames": (40, "identical values for this many frames: a stuck taxel", {"ge": 1}),
    "contact.rim_margin_m": (0.001, "hemisphere: a pressure centre this close to the top of the band is a rim "
                                    "contact, published with an unknown (NaN) normal", {"ge": 0.0}),
    "contact.skin_stiffness_pa_per_m": (0.0, "skin pressure per metre of compression: > 0 moves a contact in "
                                             "by the skin's indentation under its force (0 = not; the simulated "
                                             "skin is 2e7; calibrate by pressing a plane, docs/sensor.md)",
                                        {"ge": 0.0}),
    "contact.skin_margin_m": (0.00625, "how far the compliant skin reaches beyond the sensorised band",
                              {"ge": 0.0}),
}


class TactileSensorNode(Node):
    def __init__(self) -> None:
        super().__init__("tactile_sensor")
        p = declare_parameters(self, PARAMS)
        layout = load_layout(resolve_layout_file(p.layout_file))
        contact = ContactConfig(
            counts_per_newton=p.contact_counts_per_newton, on_threshold_n=p.contact_on_threshold_n,
            off_threshold_n=p.contact_off_threshold_n, noise_gate_sigma=p.contact_noise_gate_sigma,
            min_noise_counts=p.contact_min_noise_counts, min_active_taxels=p.contact_min_active_taxels,
            calibration_frames=p.contact_calibration_frames, stuck_frames=p.contact_stuck_frames,
            rim_margin_m=p.contact_rim_margin_m, skin_stiffness_pa_per_m=p.contact_skin_stiffness_pa_per_m,
            skin_margin_m=p.contact_skin_margin_m,
        )
        self.driver = SensorDriver(layout, contact, DriverConfig(
            max_frame_age_s=p.max_frame_age_s, pose_tolerance_s=p.pose_tolerance_s,
            pose_buffer_s=p.pose_buffer_s, clock_window_s=p.clock_window_s, pose_wait_s=p.pose_wait_s,
            device_clock_is_ros_time=p.device_clock_is_ros_time))
        self.link = SerialLink(p.port, p.baud, p.reconnect_min_s, p.reconnect_max_s)
        self.world_frame = p.world_frame
        self._connects_seen = 0
        self._rate_frames, self._rate_t = 0, time.monotonic()
        self._last_counts: dict = {}
        self._pub_contacts = self.create_publisher(PointCloud2, topics.CONTACTS, qos.OBSERVATIONS)
        self._pub_taxels = self.create_publisher(Float32MultiArray, topics.TAXELS, qos.SENSOR)
        self._pub_frames = self.create_publisher(PointCloud2, topics.CONTACT_FRAMES, qos.STATE)
        self._pub_decided = self.create_publisher(DiagnosticStatus, topics.SENSOR_DECIDED, qos.SENSOR)
        self._decided_sent_s = -np.inf
        self._contacts_sent = 0
        self._pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.create_subscription(PoseStamped, topics.FINGERTIP_POSE, self._on_pose, qos.STATE)
        steady = Clock(clock_type=ClockType.STEADY_TIME)  # serial I/O runs in wall time
        self.create_timer(p.poll_period_s, self._poll, clock=steady)
        self.create_timer(p.diagnostics_period_s, self._publish_diagnostics, clock=steady)
        self._invalid_poses = 0
        self.get_logger().info(f"tactile_sensor: {layout.n_taxels} taxels ({layout.name}), device {p.port}")

    def _on_pose(self, msg: PoseStamped) -> None:
        t = stamp_s(msg.header.stamp)
        pp, q = msg.pose.position, msg.pose.orientation
        wrong_frame = msg.header.frame_id != self.world_frame  # used as world, it would misplace the contacts
        completed = None if wrong_frame else self.driver.add_pose(t, [pp.x, pp.y, pp.z], xyzw(q))
        if completed is None:
            self._invalid_poses += 1
            self.get_logger().warn(f"ignored a fingertip pose (out of order, not finite or frame "
                                   f"'{msg.header.frame_id}' not '{self.world_frame}')", throttle_duration_sec=5.0)
            return
        for c in completed:
            self._publish_contact(c)
        self._publish_frames(self.driver.take_frame_contacts())
        self._publish_decided()

    def _publish_decided(self) -> None:
        """After the contacts: how far the frames have been judged (the commander waits for it)."""
        t = self.driver.decided_through_s
        if t > self._decided_sent_s and np.isfinite(t):
            self._decided_sent_s = t
            self._pub_decided.publish(DiagnosticStatus(
                name="tactile_sensor", message="decided", hardware_id="tactile_sensor",
                values=[KeyValue(key="decided_through_ns", value=str(ns_from_s(t))),
                        KeyValue(key="contacts_sent", value=str(self._contacts_sent))]))

    def _poll(self) -> None:
        data = self.link.poll(time.monotonic())
        if self.link.connects != self._connects_seen:  # (re)connected: a fresh stream
            self._connects_seen = self.link.connects
            self.driver.device_reset()
            self.get_logger().info(f"sensor device {self.link.port} connected ({self.link.reconnects} reconnects)")
        now_ns = self.get_clock().now().nanoseconds
        if not data or now_ns == 0:  # use_sim_time before the first /clock: frames cannot be timed
            return
        now_s = now_ns * 1e-9
        out = self.driver.feed(data, now_s)
        for stamp_s, values in out.frames:
            msg = Float32MultiArray(data=values.astype(np.float32).tolist())
            msg.layout.dim = [MultiArrayDimension(label="taxel", size=values.size, stride=values.size)]
            self._pub_taxels.publish(msg)
        self._rate_frames += len(out.frames)
        for c in out.contacts:
            self._publish_contact(c)
        self._publish_frames(out.frame_contacts)
        self._publish_decided()

    def _publish_frames(self, frames: list) -> None:
        """The per-frame stream: one point per frame in contact, an empty cloud at a release."""
        for stamp_s, c in frames:
            point = np.zeros(0 if c is None else 1, dtype=fields.CONTACT_DTYPE)
            if c is not None:
                point["x"], point["y"], point["z"] = c.point_xyz
                point["normal_x"], point["normal_y"], point["normal_z"] = c.normal_xyz
                point["force"], point["label"] = c.force_n, fields.LABEL_CONTACT
            self._pub_frames.publish(to_pointcloud2(point, self.world_frame, time_from_s(stamp_s)))

    def _publish_contact(self, c: WorldContact) -> None:
        point = np.zeros(1, dtype=fields.CONTACT_DTYPE)
        point["x"], point["y"], point["z"] = c.point_xyz
        point["normal_x"], point["normal_y"], point["normal_z"] = c.normal_xyz
        point["force"], point["label"] = c.force_n, fields.LABEL_CONTACT
        self._pub_contacts.publish(to_pointcloud2(point, self.world_frame, time_from_s(c.stamp_s)))
        self._contacts_sent += 1
        self.get_logger().info(
            f"contact at {np.round(c.point_xyz, 4).tolist()} normal {np.round(c.normal_xyz, 3).tolist()} "
            f"force {c.force_n:.3f} N")

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        rate_hz = self._rate_frames / max(now - self._rate_t, 1e-9)
        self._rate_frames, self._rate_t = 0, now
        d, s, det = self.driver.decoder.stats, self.driver.stats, self.driver.detector
        counts = {
            "frames": s.frames, "bytes_in": d.bytes_in, "startup_bytes": d.startup_bytes, "crc_errors": d.crc_errors, "bad_lengths": d.bad_lengths, "gaps": d.gaps,
            "lost_frames": d.lost_frames, "resyncs": d.resyncs, "garbage_bytes": d.garbage_bytes,
            "stale_frames": s.stale_frames, "wrong_size_frames": s.wrong_size_frames,
            "reconnects": self.link.reconnects, "disconnects": self.link.disconnects,
            "failed_connects": self.link.failed_attempts, "contacts": s.contacts,
            "refused_no_pose": s.refused_no_pose, "invalid_poses": self._invalid_poses,
            "stuck_taxels": int(det.stuck.sum()), "dead_taxels": int(det.dead.sum()),
        }
        faults = ("crc_errors", "bad_lengths", "gaps", "resyncs", "stale_frames", "wrong_size_frames",
                  "disconnects", "refused_no_pose", "stuck_taxels", "dead_taxels")
        new_faults = [k for k in faults if counts[k] != self._last_counts.get(k, 0)]
        self._last_counts = counts
        if not self.link.connected:
            level, message = DiagnosticStatus.ERROR, f"device not connected: {self.link.last_error}"
        elif d.frames == 0 and d.bytes_in > 0:
            level, message = DiagnosticStatus.WARN, "bytes but no valid frame (baud rate? protocol?)"
        elif not det.calibrated:
            level, message = DiagnosticStatus.WARN, "calibrating baseline"
        elif new_faults or counts["stuck_taxels"] or counts["dead_taxels"]:  # taxels: for as long as it lasts
            ignored = counts["stuck_taxels"] or counts["dead_taxels"]
            level, message = DiagnosticStatus.WARN, "; ".join(filter(None, [
                "faults: " + ", ".join(new_faults) if new_faults else "",
                f"taxels ignored: {counts['stuck_taxels']} stuck, {counts['dead_taxels']} dead" if ignored else ""]))
        else:
            level, message = DiagnosticStatus.OK, "streaming"
        values = [KeyValue(key="connected", value=str(self.link.connected).lower()),
                  KeyValue(key="calibrated", value=str(det.calibrated).lower()),
                  KeyValue(key="frame_rate_hz", value=f"{rate_hz:.1f}")]
        values += [KeyValue(key=k, value=str(v)) for k, v in counts.items()]
        status = DiagnosticStatus(level=level, name="tactile_sensor: device", message=message,
                                  hardware_id=self.link.port, values=values)
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._pub_diag.publish(msg)

    def close(self) -> None:
        self.link.close()


def main(args=None) -> int:
    return run_node(TactileSensorNode, args)
