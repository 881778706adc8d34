"""Graph: sim_sensor_device (pty) + tactile_sensor processes; fingertip poses from the test.

Hidden objects: the built-in 2D 'circle' (radius 4 cm, centre (0.50, 0.00)) and
3D 'sphere' (radius 5 cm, centre (0.50, 0.00, 0.05)); the truth is computed here
from that geometry.
"""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import PointCloud2

from tactile_common import fields, qos, topics
from tactile_common.pointcloud import from_pointcloud2
from tactile_common.testing import status_of, wait_for_pose_readers

pytestmark = pytest.mark.graph

CENTRE = np.array([0.50, 0.0])
RADIUS_M = 0.04
TIP_RADIUS_M = 0.010
Z_M = 0.06
SPEED_MPS = 0.02


class PoseScript:
    """Publishes the fingertip pose at 100 Hz: parked, then a straight approach."""

    def __init__(self, graph, start_xy, direction_xy):
        self.graph = graph
        self.start = np.r_[np.asarray(start_xy, float), Z_M][:3]
        d = np.r_[np.asarray(direction_xy, float), 0.0][:3]
        self.dir = d / np.linalg.norm(d)
        self.moving, self.travel_m = False, 0.0
        self.pub = graph.node.create_publisher(PoseStamped, topics.FINGERTIP_POSE, qos.STATE)
        self.device_diags = graph.collect(topics.DIAGNOSTICS, DiagnosticArray, 50, keep=status_of("sim_sensor_device"))
        graph.node.create_timer(0.01, self.publish)

    def wait_for_subscribers(self, contacts):
        """The device and the driver hear the poses; the test hears the driver's contacts."""
        wait_for_pose_readers(self.graph, self.pub, contacts, self.device_diags)

    def go(self):
        self.moving = True

    def publish(self):
        # One step per tick, not with the wall clock: a starved test process pauses the tip instead of
        # making it jump (a jump is a motion the device and the driver interpolate differently).
        now = self.graph.node.get_clock().now()
        if self.moving:
            self.travel_m = min(self.travel_m + SPEED_MPS * 0.01, 0.03)
        xyz = self.start + self.travel_m * self.dir
        msg = PoseStamped()
        msg.header.stamp = now.to_msg()
        msg.header.frame_id = topics.WORLD_FRAME
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
        msg.pose.orientation.w = 1.0
        self.pub.publish(msg)


def start_nodes(graph, link, faults=(), mode="2d"):
    obj, layout = ("circle", "taxels_ring.yaml") if mode == "2d" else ("sphere", "taxels_hemisphere.yaml")
    graph.start("device", ["sim_sensor_device", "--ros-args", "-p", f"link_path:={link}",
                           "-p", f"object:={obj}", "-p", f"mode:={mode}", "-p", "seed:=3",
                           "-p", "diagnostics_period_s:=0.25", *faults])
    graph.start("driver", ["tactile_sensor", "--ros-args", "-p", f"port:={link}",
                           "-p", f"layout_file:={layout}", "-p", "reconnect_min_s:=0.05",
                           "-p", "diagnostics_period_s:=0.25"])


def diag_values(msg):
    return {kv.key: kv.value for kv in msg.status[0].values}


def check_contact(msg, direction_xy):
    pts = from_pointcloud2(msg)
    assert len(pts) == 1 and pts["label"][0] == fields.LABEL_CONTACT
    assert msg.header.frame_id == topics.WORLD_FRAME
    p = fields.xyz(pts)[0]
    n = fields.normals(pts)[0]
    radial = (p[:2] - CENTRE) / np.linalg.norm(p[:2] - CENTRE)
    assert abs(np.linalg.norm(p[:2] - CENTRE) - RADIUS_M) < 0.002, f"contact {p} is off the circle"
    assert abs(p[2] - Z_M) < 0.002
    assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-6)
    assert math.degrees(math.acos(np.clip(n[:2] @ radial, -1, 1))) < 10.0, f"normal {n} vs radial {radial}"
    assert radial @ np.asarray(direction_xy) < -0.9, "the touched side faces the approach"
    assert pts["force"][0] > 0.0


def test_contact_from_simulated_device_through_the_driver(ros_graph, tmp_path):
    link = tmp_path / "sensor"
    diags = ros_graph.collect(topics.DIAGNOSTICS, DiagnosticArray, 10, keep=status_of("tactile_sensor"))
    contacts = ros_graph.collect(topics.CONTACTS, PointCloud2, qos.EVENTS)
    direction = np.array([math.cos(2.5), math.sin(2.5)])  # towards the upper left: touches the lower right
    start = CENTRE - direction * (RADIUS_M + TIP_RADIUS_M + 0.004)
    script = PoseScript(ros_graph, start, direction)
    start_nodes(ros_graph, link)
    ros_graph.wait_for(lambda: any(diag_values(m).get("calibrated") == "true" for m in diags), 20, "calibration")
    assert not contacts
    script.wait_for_subscribers(contacts)
    script.go()
    ros_graph.wait_for(lambda: contacts, 10, "a contact")
    ros_graph.wait_for(lambda: diags and int(diag_values(diags[-1])["contacts"]) >= 1, 5, "diagnostics")
    print("driver diagnostics:", diag_values(diags[-1]))
    check_contact(contacts[0], direction)
    codes = ros_graph.stop_all()
    assert codes == {"driver": 0, "device": 0}


def test_faults_are_counted_and_give_no_false_contact(ros_graph, tmp_path):
    link = tmp_path / "sensor"
    diags = ros_graph.collect(topics.DIAGNOSTICS, DiagnosticArray, 10, keep=status_of("tactile_sensor"))
    contacts = ros_graph.collect(topics.CONTACTS, PointCloud2, qos.EVENTS)
    direction = np.array([1.0, 0.0])
    start = CENTRE - direction * (RADIUS_M + TIP_RADIUS_M + 0.004)
    script = PoseScript(ros_graph, start, direction)
    faults = ["-p", "fault.garbage_prob:=0.05", "-p", "fault.crc_error_prob:=0.05", "-p", "fault.drop_prob:=0.05",
              "-p", "fault.stuck_taxel:=5", "-p", "fault.stuck_value:=30000", "-p", "fault.stuck_after_s:=1.0",
              "-p", "fault.disconnect_at_s:=2.0", "-p", "fault.disconnect_for_s:=0.5"]
    start_nodes(ros_graph, link, faults)

    def all_faults_counted():
        for m in diags:
            v = diag_values(m)
            if (int(v["crc_errors"]) > 0 and int(v["gaps"]) > 0 and int(v["resyncs"]) > 0
                    and int(v["reconnects"]) >= 1 and int(v["stuck_taxels"]) >= 1 and v["connected"] == "true"):
                return v
        return None

    v = ros_graph.wait_for(all_faults_counted, 20, "diagnostics counting every fault")
    assert int(v["disconnects"]) >= 1 and int(v["lost_frames"]) > 0
    assert not contacts, "faults must never produce a contact"
    assert any(m.status[0].level != b"\x00" for m in diags), "faults raise the diagnostics level"
    # the driver still senses correctly after all that
    script.wait_for_subscribers(contacts)
    script.go()
    ros_graph.wait_for(lambda: contacts, 10, "a contact after the faults")
    check_contact(contacts[0], direction)


def test_3d_contact_on_a_sphere_with_the_hemispherical_tip(ros_graph, tmp_path):
    centre, radius = np.array([0.50, 0.0, 0.05]), 0.05
    link = tmp_path / "sensor"
    diags = ros_graph.collect(topics.DIAGNOSTICS, DiagnosticArray, 10, keep=status_of("tactile_sensor"))
    contacts = ros_graph.collect(topics.CONTACTS, PointCloud2, qos.EVENTS)
    direction = np.array([0.4, 0.2, -1.0]) / np.linalg.norm([0.4, 0.2, -1.0])  # down, onto the cap
    script = PoseScript(ros_graph, [0.0, 0.0], [1.0, 0.0])
    script.start = centre - direction * (radius + TIP_RADIUS_M + 0.004)
    script.dir = direction
    start_nodes(ros_graph, link, mode="3d")
    ros_graph.wait_for(lambda: any(diag_values(m).get("calibrated") == "true" for m in diags), 20, "calibration")
    script.wait_for_subscribers(contacts)
    script.go()
    ros_graph.wait_for(lambda: contacts, 10, "a contact")
    pts = from_pointcloud2(contacts[0])
    p, n = fields.xyz(pts)[0], fields.normals(pts)[0]
    radial = (p - centre) / np.linalg.norm(p - centre)
    assert abs(np.linalg.norm(p - centre) - radius) < 0.002, f"contact {p} is off the sphere"
    assert math.degrees(math.acos(np.clip(n @ radial, -1, 1))) < 10.0, f"normal {n} vs radial {radial}"
    assert radial @ direction < -0.9
