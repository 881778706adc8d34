"""sim_rig + arm_commander processes: a touch that misses gives a free-space point; unreachable goals move nothing."""

import time
from pathlib import Path as FsPath

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, PointCloud2
from trajectory_msgs.msg import JointTrajectory

from tactile_common import fields, qos, stamps, topics
from tactile_common.pointcloud import from_pointcloud2, to_pointcloud2

from graph_helpers import done_values, goal_and_path

pytestmark = pytest.mark.graph

ROOT = FsPath(__file__).resolve().parents[2]
SIM = ["sim_rig", "--ros-args", "--params-file", str(ROOT / "src/tactile_sim/config/sim_rig.yaml"),
       "-p", "sensor_enabled:=false", "-p", "real_time_factor:=4.0"]
ARM = ["arm_commander", "--ros-args", "--params-file", str(ROOT / "src/tactile_driver/config/arm_commander.yaml"),
       "-p", "use_sim_time:=true", "-p", "dwell_s:=0.1", "-p", "watchdog_timeout_s:=2.0"]
NO_START = ["-p", "move_to_start:=false"]
APPROACH_M = 0.01 + 0.02  # standoff + max depth: the skin goes max depth beyond the candidate (config defaults)


def _publish_touch(graph, pre, direction, path, stamp_ns):
    goal_pub = graph.node.create_publisher(PoseStamped, topics.GOAL, qos.EVENTS)
    path_pub = graph.node.create_publisher(Path, topics.PATH, qos.EVENTS)
    graph.wait_for(lambda: goal_pub.get_subscription_count() and path_pub.get_subscription_count(), 20, "commander subscriptions")
    goal, path_msg = goal_and_path(pre, direction, path, stamp_ns)
    path_pub.publish(path_msg)  # path first: pairing must not depend on order
    goal_pub.publish(goal)


def test_missed_touch_gives_free_space_then_unreachable_goal_moves_nothing(ros_graph):
    g = ros_graph
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    contacts = g.collect(topics.CONTACTS, PointCloud2, qos.EVENTS)
    trajs = g.collect(topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    g.start("sim", SIM)
    g.start("arm", ARM + NO_START)
    g.wait_for(lambda: len(poses) > 5 and done.publishers and contacts.publishers and trajs.publishers, 30,
               "fingertip poses and the commander's writers")
    # Far from the object (circle at (0.5, 0)): the approach ends in free space.
    pre, direction = np.array([0.40, 0.20, 0.06]), np.array([0.0, 1.0, 0.0])
    path = np.array([[0.50, 0.0, 0.35], [0.42, 0.12, 0.10], pre])
    _publish_touch(g, pre, direction, path, 1_000_000_123)
    g.wait_for(lambda: len(done) >= 1, 40, "touch_done")
    v = done_values(done[0])
    assert done[0].message == "free_space", v
    assert v["goal_stamp_ns"] == "1000000123"
    free = [from_pointcloud2(m) for m in contacts]
    assert len(free) == 1 and free[0]["label"][0] == fields.LABEL_FREE_SPACE
    np.testing.assert_allclose(fields.xyz(free[0])[0], pre + APPROACH_M * direction, atol=1e-3)
    assert int(v["observation_stamp_ns"]) == stamps.stamp_ns(contacts[0].header.stamp)
    path_len = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    assert abs(float(v["travel_m"]) - (path_len + 2 * APPROACH_M)) < 0.01
    # Back at the pre-touch pose.
    g.wait_for(lambda: len(poses) and np.linalg.norm([poses[-1].pose.position.x - pre[0], poses[-1].pose.position.y - pre[1],
                                                      poses[-1].pose.position.z - pre[2]]) < 1e-3, 10, "tip at pre-touch")
    n_traj = len(trajs)
    assert n_traj == 3  # path, approach, retract

    # Outside the safety box (below the table floor): reported, nothing sent.
    _publish_touch(g, np.array([0.40, 0.20, 0.005]), direction, [[0.40, 0.20, 0.06]], 2_000_000_000)
    g.wait_for(lambda: len(done) >= 2, 20, "second touch_done")
    assert done[1].message == "unreachable" and "safety box" in done_values(done[1])["reason"]
    assert done[1].level == DiagnosticStatus.WARN
    # Inside the box but out of the arm's reach (IK fails): reported, nothing sent.
    far = np.array([0.74, 0.29, 0.55])
    _publish_touch(g, far, direction, [[0.60, 0.20, 0.40], far], 2_500_000_000)
    g.wait_for(lambda: len(done) >= 3, 20, "third touch_done")
    assert done[2].message == "unreachable" and "IK found no solution" in done_values(done[2])["reason"]
    assert done_values(done[2])["travel_m"] == "0.000000"
    t_end = time.monotonic()
    g.wait_for(lambda: time.monotonic() > t_end + 0.5, 5, "late trajectories")
    assert len(trajs) == n_traj
    assert g.procs["arm"].alive() and g.procs["sim"].alive()


def test_moves_to_the_start_position_over_the_object_then_touches(ros_graph):
    g = ros_graph
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    start = np.array([0.33, 0.0, 0.06])
    g.start("sim", SIM)
    g.start("arm", ARM + ["-p", "start_tip_xyz_m:=[0.33, 0.0, 0.06]"])

    def tip(m):
        return np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])

    g.wait_for(lambda: done.publishers, 30, "the commander's touch_done writer")
    # A goal sent before the tip is at the start waits for it.
    _publish_touch(g, np.array([0.33, 0.0, 0.06]), np.array([0.0, 1.0, 0.0]), [[0.33, 0.0, 0.06]], 6)
    g.wait_for(lambda: poses and np.linalg.norm(tip(poses[-1]) - start) < 3e-3, 30, "tip at the start position")
    assert not done
    xyz = np.array([tip(m) for m in poses])
    low = xyz[:, 2] < 0.20  # below the clearance height only outside the object's footprint
    assert np.all(np.linalg.norm(xyz[low, :2] - [0.5, 0.0], axis=1) > 0.1)
    g.wait_for(lambda: done, 30, "the queued touch")
    assert done[0].message == "free_space"


def test_a_contact_still_on_its_way_at_the_end_of_the_approach_is_not_taken_for_free_space(ros_graph):
    """The driver's contact for a frame just before full depth can arrive after the approach ends:
    the commander waits ``contact_latency_s`` before it calls the probe a miss."""
    g = ros_graph
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    contacts = g.collect(topics.CONTACTS, PointCloud2, qos.EVENTS)
    trajs = g.collect(topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    clock = g.collect(topics.CLOCK, Clock, qos.CLOCK)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    g.start("sim", SIM)
    g.start("arm", ARM + NO_START + ["-p", "contact_latency_s:=4.0"])  # 1 s of wall time at x4
    contact_pub = g.node.create_publisher(PointCloud2, topics.CONTACTS, qos.EVENTS)
    g.wait_for(lambda: clock and len(poses) > 5 and done.publishers and trajs.publishers
               and contact_pub.get_subscription_count(), 30, "the rig's clock and the commander's joint states")
    pre, direction = np.array([0.40, 0.20, 0.06]), np.array([0.0, 1.0, 0.0])
    _publish_touch(g, pre, direction, [[0.42, 0.12, 0.10], pre], 3_000_000_000)
    g.wait_for(lambda: len(trajs) >= 2, 40, "the approach trajectory")

    def sim_s():
        return stamps.stamp_s(clock[-1].clock)

    end_s = sim_s() + stamps.stamp_s(trajs[1].points[-1].time_from_start)
    g.wait_for(lambda: sim_s() > end_s + 0.5, 20, "the end of the approach")
    assert not done  # no free-space verdict yet
    late = np.zeros(1, dtype=fields.CONTACT_DTYPE)
    late["x"], late["y"], late["z"], late["label"] = pre[0], pre[1] + APPROACH_M, pre[2], fields.LABEL_CONTACT
    late_ns = stamps.ns_from_s(end_s - 0.05)
    contact_pub.publish(to_pointcloud2(late, topics.WORLD_FRAME, stamps.time_from_ns(late_ns)))
    g.wait_for(lambda: done, 30, "touch_done")
    v = done_values(done[0])
    assert done[0].message == "contact", v
    assert int(v["observation_stamp_ns"]) == late_ns
    assert all(from_pointcloud2(m)["label"][0] == fields.LABEL_CONTACT for m in contacts)  # no free-space point


def test_an_approach_stops_when_the_sensor_falls_silent_and_is_repeated_once_it_is_back(ros_graph):
    """The test plays the sensor driver's progress messages (the rig's sensor is off): they stop in the
    middle of the approach. The arm must stop within about ``sensor_silence_s`` (not press on blind),
    stay there while the driver is silent, then retract and make the same approach again."""
    g = ros_graph
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    trajs = g.collect(topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    clock = g.collect(topics.CLOCK, Clock, qos.CLOCK)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    g.start("sim", SIM)
    # 1 s of node clock (250 ms wall at x4: this test's own driver emulation must not lag that much under
    # load); a 50 mm depth gives a 3 s approach, so the stop comes well before its end
    g.start("arm", ARM + NO_START + ["-p", "sensor_silence_s:=1.0", "-p", "max_depth_m:=0.05"])
    decided_pub = g.node.create_publisher(DiagnosticStatus, topics.SENSOR_DECIDED, qos.SENSOR)
    silent = [False]

    def play_driver():
        if clock and not silent[0]:
            decided_pub.publish(DiagnosticStatus(name="tactile_sensor", message="decided", values=[
                KeyValue(key="decided_through_ns", value=str(stamps.stamp_ns(clock[-1].clock))),
                KeyValue(key="contacts_sent", value="0")]))

    g.node.create_timer(0.01, play_driver)
    g.wait_for(lambda: clock and len(poses) > 5 and done.publishers and trajs.publishers
               and decided_pub.get_subscription_count(), 30, "the rig's clock and the commander's joint states")

    def sim_s():
        return stamps.stamp_s(clock[-1].clock)

    def tip(m):
        return np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])

    pre, direction = np.array([0.40, 0.20, 0.06]), np.array([0.0, 1.0, 0.0])  # free space: no contact
    _publish_touch(g, pre, direction, [[0.42, 0.12, 0.10], pre], 4_000_000_000)
    g.wait_for(lambda: len(trajs) >= 2, 40, "the approach trajectory")
    start_s = stamps.stamp_s(trajs[1].header.stamp)
    approach = np.array([p.positions for p in trajs[1].points])
    g.wait_for(lambda: sim_s() > start_s + 0.4, 20, "the approach under way")
    silent[0], silent_s = True, sim_s()
    g.wait_for(lambda: len(trajs) >= 3, 20, "the stop")
    assert not trajs[2].points  # an empty trajectory: stop and hold
    g.wait_for(lambda: sim_s() > silent_s + 1.5, 20, "a while of silence")
    assert len(trajs) == 3 and not done  # stopped and waiting, not retracting blind
    # The tip went at most about sensor_silence_s (plus the control tick and delivery) at approach speed.
    moved_m = float(np.linalg.norm(tip(poses[-1]) - pre))
    expected_m = (silent_s - start_s) * 0.02
    assert moved_m < expected_m + 1.1 * 0.02, (moved_m, expected_m)
    silent[0] = False
    g.wait_for(lambda: done, 40, "touch_done")
    v = done_values(done[0])
    assert done[0].message == "free_space" and "repeated" in v["reason"], v
    # path, approach, stop, retract, approach, retract; should the emulated driver lag by the limit again
    # under load, each further stop is the same triple: stop, retract, the same approach
    assert len(trajs) >= 6 and (len(trajs) - 6) % 3 == 0, len(trajs)
    for k in range(4, len(trajs) - 1, 3):
        assert not trajs[k - 2].points  # a stop before each retract
        np.testing.assert_array_equal(np.array([p.positions for p in trajs[k].points]), approach)  # the same motion


def test_the_commander_reports_acting_on_contacts_only_once_the_contacts_the_driver_sent_are_here(ros_graph):
    """/arm/acted_through (what the simulated rig's clock waits for) follows the driver's
    /tactile/decided_through while every contact it announced has arrived, and stops at the last
    such stamp while one is on its way; the contact's arrival lets it go on."""
    g = ros_graph
    acted = g.collect(topics.ARM_ACTED, DiagnosticStatus, qos.SENSOR)
    clock = g.collect(topics.CLOCK, Clock, qos.CLOCK)
    g.start("sim", SIM)
    g.start("arm", ARM + NO_START)
    decided_pub = g.node.create_publisher(DiagnosticStatus, topics.SENSOR_DECIDED, qos.SENSOR)
    contact_pub = g.node.create_publisher(PointCloud2, topics.CONTACTS, qos.OBSERVATIONS)
    sent = [0]
    published_ns = []

    def play_driver():
        if clock:
            ns = stamps.stamp_ns(clock[-1].clock)
            if not published_ns or ns > published_ns[-1]:
                published_ns.append(ns)
                decided_pub.publish(DiagnosticStatus(name="tactile_sensor", message="decided", values=[
                    KeyValue(key="decided_through_ns", value=str(ns)), KeyValue(key="contacts_sent", value=str(sent[0]))]))

    g.node.create_timer(0.01, play_driver)

    def acted_ns():
        return [int(done_values(m)["acted_through_ns"]) for m in acted]

    g.wait_for(lambda: len(acted) > 5, 30, "the commander's acted_through")
    assert set(acted_ns()) <= set(published_ns) and acted_ns() == sorted(acted_ns())
    # The driver announces a contact that has not arrived: acted_through stays before it.
    sent[0], n_before = 1, len(published_ns)
    g.wait_for(lambda: len(published_ns) > n_before, 10, "progress")
    first_held_ns = published_ns[n_before]  # the first one to announce the contact
    g.wait_for(lambda: published_ns[-1] > first_held_ns + 500_000_000, 30, "0.5 s of progress with the contact missing")
    assert max(acted_ns()) < first_held_ns, (max(acted_ns()), first_held_ns)
    # The contact arrives (far from any motion: the commander is idle, it only counts it).
    cloud = np.zeros(1, dtype=fields.CONTACT_DTYPE)
    cloud["x"], cloud["y"], cloud["z"], cloud["label"] = 0.5, 0.0, 0.06, fields.LABEL_CONTACT
    contact_pub.publish(to_pointcloud2(cloud, topics.WORLD_FRAME, stamps.time_from_ns(first_held_ns)))
    g.wait_for(lambda: max(acted_ns()) > first_held_ns + 500_000_000, 30, "acted_through after the contact")
