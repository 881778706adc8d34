"""Sensor faults, one per test: the simulated device (sim_sensor_device, fault_* parameters) + tactile_sensor.

Each fault must be counted on /diagnostics (and raise its level), give no
false contact while the fingertip rests 4 mm off the object, and leave the
driver sensing: an approach afterwards gives one contact on the true surface
(the built-in 2D 'circle', radius 4 cm at (0.50, 0.00); computed here). The
last test feeds the driver invalid fingertip poses (its message input).
"""

import math
import os
import signal

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import PointCloud2

from tactile_common import fields, qos, topics
from tactile_common.pointcloud import from_pointcloud2
from tactile_common.testing import status_of, wait_for_pose_readers
from tactile_common.stamps import time_from_s

from fault_helpers import diag_values, pose_msg

pytestmark = pytest.mark.graph

CENTRE, RADIUS_M, TIP_RADIUS_M, Z_M = np.array([0.50, 0.0]), 0.04, 0.010, 0.06
SPEED_MPS = 0.02
PERIOD_S = 0.01  # pose period
DIRECTION = np.array([math.cos(2.5), math.sin(2.5)])  # the approach touches the circle's lower right


class PoseScript:
    """Fingertip poses at 100 Hz: parked 4 mm off the circle, then a straight approach; extra (bad) poses on demand."""

    def __init__(self, graph):
        self.graph = graph
        self.start = np.r_[CENTRE - DIRECTION * (RADIUS_M + TIP_RADIUS_M + 0.004), Z_M]
        self.dir = np.r_[DIRECTION, 0.0]
        self.moving, self.travel_m = False, 0.0
        self.extra: list = []  # functions now_s -> PoseStamped, each published once
        self.ticks = 0
        self.pub = graph.node.create_publisher(PoseStamped, topics.FINGERTIP_POSE, qos.STATE)
        self.device_diags = graph.collect(topics.DIAGNOSTICS, DiagnosticArray, 50, keep=status_of("sim_sensor_device"))
        graph.node.create_timer(PERIOD_S, self.publish)

    def wait_for_subscribers(self, contacts):
        wait_for_pose_readers(self.graph, self.pub, contacts, self.device_diags)

    def go(self):
        self.moving = True

    def publish(self):
        # The tip advances one step per tick, not with the wall clock: if this process is starved, the tip
        # pauses instead of jumping (a jump between two poses is a motion the device and driver cannot agree on).
        now = self.graph.node.get_clock().now()
        t = now.nanoseconds * 1e-9
        if self.moving:
            self.travel_m = min(self.travel_m + SPEED_MPS * PERIOD_S, 0.03)
        self.pub.publish(pose_msg(self.start + self.travel_m * self.dir, topics.WORLD_FRAME, now.to_msg()))
        self.ticks += 1
        if self.extra and self.ticks % 10 == 0:  # spaced out between the valid poses
            self.pub.publish(self.extra.pop(0)(t))


def _start(graph, link, *faults, driver_params=(), heard=None):
    """The device and the driver. With ``heard`` (the test's /diagnostics list): the driver first, and the
    device (whose faults run on its own clock) only once the test hears the driver, so a fault the driver
    reports for a moment cannot fall before the test's reader is matched (discovery is slow under load)."""
    device = ["sim_sensor_device", "--ros-args", "-p", f"link_path:={link}", "-p", "object:=circle",
              "-p", "mode:=2d", "-p", "seed:=3", "-p", "diagnostics_period_s:=0.25", *faults]
    driver = ["tactile_sensor", "--ros-args", "-p", f"port:={link}", "-p", "layout_file:=taxels_ring.yaml",
              "-p", "reconnect_min_s:=0.05", "-p", "reconnect_max_s:=0.1", "-p", "diagnostics_period_s:=0.25",
              *[a for kv in driver_params for a in ("-p", kv)]]
    if heard is None:
        graph.start("device", device)
        graph.start("driver", driver)
        return
    graph.start("driver", driver)
    graph.wait_for(lambda: heard, 30, "the driver's /diagnostics (no device yet)")
    graph.start("device", device)


def _reports_a_fault(msg) -> bool:
    """A driver status that reports a fault: a counted one, ignored taxels, or a lost connection (not the
    calibration, nor the wait for a device that was never there)."""
    status, v = msg.status[0], diag_values(msg)
    lost = v["connected"] == "false" and int(v["disconnects"]) > 0
    return status.level in (DiagnosticStatus.WARN, DiagnosticStatus.ERROR) and (
        status.message.startswith("faults:") or "taxels ignored" in status.message or lost)


STALE = ("stale_frames", "refused_no_pose")  # frames the driver could not use in time (it was starved)


def _stale(diags) -> int:
    return sum(int(diag_values(diags[-1])[k]) for k in STALE) if diags else 0


def _approach_and_check(graph, script, contacts, diags):
    """Approach; one contact on the touched side of the circle.

    On the surface within 2 mm, unless the driver had to drop frames during the approach (a starved
    process on a loaded machine: the simulated finger goes on into the object until a frame is used);
    then the contact may lie inside the circle, never outside it (that would be a false contact).
    """
    stale_before = _stale(diags)
    script.go()
    graph.wait_for(lambda: contacts, 15, "a contact")
    n = len(diags)
    graph.wait_for(lambda: len(diags) > n, 5, "diagnostics after the contact")
    late = _stale(diags) > stale_before
    _check_contact(contacts[0], late, diag_values(diags[-1]))


def _check_contact(msg, late=False, diag=None):
    pts = from_pointcloud2(msg)
    assert len(pts) == 1 and pts["label"][0] == fields.LABEL_CONTACT and msg.header.frame_id == topics.WORLD_FRAME
    p, n = fields.xyz(pts)[0], fields.normals(pts)[0]
    radial = (p[:2] - CENTRE) / np.linalg.norm(p[:2] - CENTRE)
    off_m = np.linalg.norm(p[:2] - CENTRE) - RADIUS_M
    if late:
        print(f"frames dropped during the approach (starved driver): contact {off_m * 1000:.1f} mm off", diag)
    assert off_m < 0.002 and (late or off_m > -0.002), f"contact {p} is off the circle by {off_m * 1000:.1f} mm; {diag}"
    assert abs(p[2] - Z_M) < 0.002
    assert math.degrees(math.acos(np.clip(n[:2] @ radial, -1, 1))) < 10.0, f"normal {n} vs radial {radial}"
    assert radial @ DIRECTION < -0.9, "the touched side faces the approach"


FAULTS = {  # name: (device parameters, the diagnostics that must count it)
    "garbage_bytes": (["fault.garbage_prob:=0.05"], ("resyncs", "garbage_bytes")),
    "crc_errors": (["fault.crc_error_prob:=0.05"], ("crc_errors",)),
    "dropped_frames": (["fault.drop_prob:=0.05"], ("gaps", "lost_frames")),
    "stuck_taxel": (["fault.stuck_taxel:=5", "fault.stuck_value:=30000", "fault.stuck_after_s:=1.0"],
                    ("stuck_taxels",)),
    "disconnect": (["fault.disconnect_at_s:=2.0", "fault.disconnect_for_s:=0.5"], ("disconnects", "reconnects")),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_sensor_fault_is_reported_gives_no_false_contact_and_the_driver_still_senses(ros_graph, tmp_path, fault):
    g = ros_graph
    params, counters = FAULTS[fault]
    diags = g.collect(topics.DIAGNOSTICS, DiagnosticArray, 50, keep=status_of("tactile_sensor"))
    contacts = g.collect(topics.CONTACTS, PointCloud2, qos.OBSERVATIONS)
    script = PoseScript(g)
    _start(g, tmp_path / "sensor", *[a for kv in params for a in ("-p", kv)], heard=diags)

    def counted():
        for m in diags:
            v = diag_values(m)
            if all(int(v[c]) > 0 for c in counters) and v["connected"] == "true" and v["calibrated"] == "true":
                return v
        return None

    v = g.wait_for(counted, 30, f"/diagnostics counting {counters}")
    assert not contacts, "a fault must never produce a contact"
    assert any(_reports_a_fault(m) for m in diags), ("the fault raises the level",
                                                     [(m.status[0].level, m.status[0].message) for m in diags])
    if fault == "stuck_taxel":  # a state, not an event: reported for as long as it lasts
        n = len(diags)
        g.wait_for(lambda: len(diags) > n + 2, 5, "later diagnostics")
        assert diags[-1].status[0].level == DiagnosticStatus.WARN and "stuck" in diags[-1].status[0].message, \
            (diags[-1].status[0].message, diag_values(diags[-1]))
    script.wait_for_subscribers(contacts)
    _approach_and_check(g, script, contacts, diags)
    assert g.procs["driver"].alive() and g.procs["device"].alive()


def test_invalid_fingertip_poses_are_counted_and_contacts_still_use_the_valid_ones(ros_graph, tmp_path):
    g = ros_graph
    diags = g.collect(topics.DIAGNOSTICS, DiagnosticArray, 50, keep=status_of("tactile_sensor"))
    contacts = g.collect(topics.CONTACTS, PointCloud2, qos.OBSERVATIONS)
    script = PoseScript(g)
    _start(g, tmp_path / "sensor")
    g.wait_for(lambda: any(diag_values(m).get("calibrated") == "true" for m in diags), 30, "calibration")
    script.wait_for_subscribers(contacts)
    far = [0.30, 0.20, 0.06]  # a plausible position: used as world, it would move the contact there
    script.extra = [
        lambda t: pose_msg([np.nan, 0.0, Z_M], topics.WORLD_FRAME, time_from_s(t)),
        lambda t: pose_msg(far, topics.WORLD_FRAME, time_from_s(t), q_xyzw=(0.0, 0.0, 0.0, 0.0)),
        lambda t: pose_msg(far, topics.WORLD_FRAME, time_from_s(t - 1.0)),  # older than the newest
        lambda t: pose_msg(far, "base_link", time_from_s(t + 0.001)),  # another frame
    ]
    n_bad = len(script.extra)
    g.wait_for(lambda: not script.extra and diags and int(diag_values(diags[-1])["invalid_poses"]) >= n_bad, 10,
               "the invalid poses counted")
    assert int(diag_values(diags[-1])["invalid_poses"]) == n_bad
    assert not contacts
    _approach_and_check(g, script, contacts, diags)


def test_a_stalled_device_writes_each_frame_at_the_pose_of_its_time(ros_graph, tmp_path):
    """The device process stops for the first 10 mm of the approach (SIGSTOP: what a starved process does);
    the poses queue. Resumed, it must write the frames of the stall at the poses of their times, so the
    contact lies on the circle. (Before: its timer ran before the queued poses and wrote those frames at
    the parked pose, and the contact came out 6 mm deep.) The driver judges every frame however late
    (``max_frame_age_s`` 5 s, as on the simulated rig), so only the device is under test."""
    g = ros_graph
    diags = g.collect(topics.DIAGNOSTICS, DiagnosticArray, 50, keep=status_of("tactile_sensor"))
    contacts = g.collect(topics.CONTACTS, PointCloud2, qos.OBSERVATIONS)
    script = PoseScript(g)
    _start(g, tmp_path / "sensor", driver_params=["max_frame_age_s:=5.0"])
    g.wait_for(lambda: any(diag_values(m).get("calibrated") == "true" for m in diags), 30, "calibration")
    script.wait_for_subscribers(contacts)
    pid = g.procs["device"].popen.pid
    os.killpg(pid, signal.SIGSTOP)
    try:
        script.go()
        g.wait_for(lambda: script.travel_m >= 0.010, 10, "the tip 6 mm past the surface while the device is stopped")
    finally:
        os.killpg(pid, signal.SIGCONT)
    g.wait_for(lambda: contacts, 15, "a contact")
    _check_contact(contacts[0], diag=diag_values(diags[-1]) if diags else None)
