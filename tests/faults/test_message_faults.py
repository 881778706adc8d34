"""Malformed messages on every input topic: rejected with a warning and counted; the node keeps running.

Each test starts one node, sends it every kind of bad message on one input,
then a valid one, and checks that the valid one is processed (the node is
alive and its state was not spoiled by the bad ones). Publishers use the
topic's own QoS profile (tactile_common.qos). The sensor driver's fingertip
pose input is tested in test_sensor_faults.py (it needs the device).
"""

from pathlib import Path as FsPath

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.duration import Duration
from rclpy.qos import QoSProfile
from sensor_msgs.msg import PointCloud2, PointField
from trajectory_msgs.msg import JointTrajectory

from tactile_common import fields, qos, topics
from tactile_common.cycle import PlanRequest
from tactile_common.cycle_msgs import answer_from_msg, request_msg
from tactile_common.pointcloud import from_pointcloud2, to_pointcloud2
from tactile_planner.synthetic import sphere_map

from fault_helpers import ARM_YAML, done_values, goal_and_path, pose_msg

pytestmark = pytest.mark.graph

ROOT = FsPath(__file__).resolve().parents[2]
PLANNER_YAML = ROOT / "src/tactile_planner/config/soc_planner.yaml"
MAP_READER = QoSProfile(depth=50, reliability=qos.MAP.reliability, durability=qos.MAP.durability)
CENTRE, RADIUS = np.array([0.5, 0.0]), 0.05


def _contact(angle_rad=0.3, label=1) -> np.ndarray:
    p = np.zeros(1, dtype=fields.CONTACT_DTYPE)
    n = np.array([np.cos(angle_rad), np.sin(angle_rad)])
    p["x"], p["y"] = CENTRE + RADIUS * n
    p["z"], p["normal_x"], p["normal_y"], p["force"], p["label"] = 0.06, n[0], n[1], 1.0, label
    return p


def _broken_clouds(valid: PointCloud2) -> dict:
    """Clouds whose layout is wrong, each derived from a valid one (same stamp and frame)."""

    def copy() -> PointCloud2:
        m = PointCloud2(header=valid.header, height=valid.height, width=valid.width, is_bigendian=False,
                        point_step=valid.point_step, row_step=valid.row_step, is_dense=valid.is_dense,
                        data=bytes(valid.data))
        m.fields = [PointField(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                    for f in valid.fields]
        return m

    out = {}
    m = copy()
    m.data = bytes(valid.data)[:-5]
    out["truncated data"] = m
    m = copy()
    m.width = 1000  # declares more points than the row holds
    out["width beyond row_step"] = m
    m = copy()
    m.width, m.row_step = 1000, 1000 * valid.point_step  # declares more points than the data holds
    out["oversized declaration"] = m
    m = copy()
    m.fields = [f for f in m.fields if f.name != m.fields[-1].name]
    out["a field missing"] = m
    m = copy()
    m.fields[0].offset = m.point_step - 2
    out["field overruns point_step"] = m
    m = copy()
    m.fields[1].datatype = 99
    out["unknown datatype"] = m
    m = copy()
    m.fields[2].count = 3
    out["field count 3"] = m
    return out


def test_estimator_rejects_bad_contact_clouds_and_keeps_mapping(ros_graph):
    g = ros_graph
    g.start("gpis", ["gpis_estimator", "--ros-args", "-p", "lattice.points_per_axis_2d:=32"])
    maps = g.collect(topics.VARIANCE_MAP, PointCloud2, MAP_READER)
    g.wait_for(lambda: maps, 30, "the prior map")
    pub = g.node.create_publisher(PointCloud2, topics.CONTACTS, qos.OBSERVATIONS)
    g.wait_for(lambda: pub.get_subscription_count() > 0, 20, "the estimator's subscription")

    bad = []
    nan, inf, far = _contact(), _contact(), _contact()
    nan["x"], inf["y"], far["x"] = np.nan, np.inf, 2.0
    bad += [to_pointcloud2(nan, "world"), to_pointcloud2(inf, "world"), to_pointcloud2(far, "world"),
            to_pointcloud2(_contact(), "base_link")]
    bad += list(_broken_clouds(to_pointcloud2(_contact(), "world")).values())
    # the label as a float, NaN: not a label
    flabel = np.zeros(1, dtype=[(n, np.float64) for n in fields.CONTACT_DTYPE.names])
    for n in fields.CONTACT_DTYPE.names:
        flabel[n] = _contact()[n]
    flabel["label"] = np.nan
    bad.append(to_pointcloud2(flabel, "world"))
    # oversized: thousands of points in one message (the contract: one point per touch); each would be a GP update
    rng = np.random.default_rng(0)
    many = np.zeros(5000, dtype=fields.CONTACT_DTYPE)
    many["x"], many["y"], many["z"] = rng.uniform(0.36, 0.64, 5000), rng.uniform(-0.14, 0.14, 5000), 0.06
    many["label"] = fields.LABEL_FREE_SPACE
    bad.append(to_pointcloud2(many, "world"))
    for i, msg in enumerate(bad, start=1):
        msg.header.stamp = Time(sec=i)
        pub.publish(msg)
    last = len(bad) + 1
    pub.publish(to_pointcloud2(_contact(), "world", Time(sec=last)))
    g.wait_for(lambda: any(m.header.stamp.sec == last for m in maps), 30, "the map of the valid contact")
    log = g.procs["gpis"].log()
    assert f"observation rejected ({len(bad)} so far)" in log, log
    assert f"observation rejected ({len(bad) + 1} so far)" not in log, log
    # the valid contact is in the estimate: the variance at its nearest lattice node collapsed
    prior, final = from_pointcloud2(maps[0]), from_pointcloud2(maps[-1])
    lat = prior["kind"] == fields.KIND_LATTICE
    c = fields.xyz(_contact())[0, :2]
    i = np.argmin(((np.stack([prior["x"], prior["y"]], 1)[lat] - c) ** 2).sum(1))
    assert final["variance"][final["kind"] == fields.KIND_LATTICE][i] < 0.2 * prior["variance"][lat][i]


def _status_values(msg) -> dict:
    return {kv.key: kv.value for kv in msg.values}


def test_planner_rejects_bad_maps_tips_and_requests_and_plans_on_the_last_good_map(ros_graph):
    g = ros_graph
    g.start("planner", ["soc_planner", "--ros-args", "--params-file", str(PLANNER_YAML)])
    node = g.node
    goals = g.collect(topics.GOAL, PoseStamped, qos.EVENTS)
    paths = g.collect(topics.PATH, Path, qos.EVENTS)
    status = g.collect("/planner/status", DiagnosticStatus, qos.EVENTS)
    pub_map = node.create_publisher(PointCloud2, topics.VARIANCE_MAP, qos.MAP)
    pub_tip = node.create_publisher(PoseStamped, topics.FINGERTIP_POSE, qos.SENSOR)
    pub_req = node.create_publisher(DiagnosticStatus, "/planner/request", qos.EVENTS)
    pub_done = node.create_publisher(DiagnosticStatus, topics.TOUCH_DONE, qos.EVENTS)
    g.wait_for(lambda: pub_map.get_subscription_count() and pub_tip.get_subscription_count()
               and pub_req.get_subscription_count() and pub_done.get_subscription_count()
               and goals.publishers and paths.publishers and status.publishers,
               30, "planner subscriptions and writers")

    def send_map(msg):  # latched depth 1: each map delivered before the next replaces it
        pub_map.publish(msg)
        assert pub_map.wait_for_all_acked(Duration(seconds=20))

    good = sphere_map(64, 2, seed=3)
    send_map(to_pointcloud2(good, "world", Time(sec=1)))
    # the planner has taken the good map: it answers a request on it
    pub_req.publish(request_msg(PlanRequest(request_id=19, min_map_stamp_ns=10**9, start_xyz_m=(0.40, -0.10, 0.06))))
    g.wait_for(lambda: any(answer_from_msg(s).request_id == 19 and s.message == "ok" for s in status), 20,
               "the answer to request 19")
    n_bad = 0
    no_mean = good[[n for n in good.dtype.names if n != "mean"]]
    nan_map = good.copy()
    nan_map["mean"][5] = np.nan
    shuffled = good.copy()
    shuffled["kind"][:3] = fields.KIND_CANDIDATE  # candidates before the lattice
    bad_maps = [to_pointcloud2(no_mean, "world"), to_pointcloud2(nan_map, "world"),
                to_pointcloud2(shuffled, "world"), to_pointcloud2(good, "base_link"),
                *_broken_clouds(to_pointcloud2(good, "world")).values()]
    for i, msg in enumerate(bad_maps, start=2):
        msg.header.stamp = Time(sec=i)
        send_map(msg)
        n_bad += 1
        # the reader keeps one map (depth 1): let the planner take this one before the next replaces it
        g.wait_for(lambda: f"invalid variance map ignored ({n_bad} so far)" in g.procs["planner"].log(), 10,
                   f"bad map {n_bad} taken")
    # bad tips: not finite, wrong frame (a plausible position in another frame must not be used as world)
    for tip in (pose_msg([np.nan, 0.0, 0.06]), pose_msg([0.60, 0.10, 0.06], frame_id="base_link")):
        pub_tip.publish(tip)
        assert pub_tip.wait_for_all_acked(Duration(seconds=20))
        n_bad += 1
    # bad requests: no id, a non-numeric stamp, a start that is not 3 finite numbers, a negative count
    for values in ({"min_map_stamp_ns": "0"}, {"request_id": "5", "min_map_stamp_ns": "soon"},
                   {"request_id": "6", "start_xyz_m": "0.4,nan,0.06"}, {"request_id": "6", "start_xyz_m": "1,2"},
                   {"request_id": "7", "misses_before_contact": "-1"}):
        pub_req.publish(DiagnosticStatus(name="request", values=[KeyValue(key=k, value=v)
                                                                 for k, v in values.items()]))
        n_bad += 1
    # bad touch reports: an unknown outcome, a goal stamp that is not a number
    for outcome, stamp in (("exploded", "1"), ("unreachable", "one")):
        pub_done.publish(DiagnosticStatus(name="touch", message=outcome,
                                          values=[KeyValue(key="goal_stamp_ns", value=stamp)]))
        n_bad += 1
    assert pub_done.wait_for_all_acked(Duration(seconds=20)) and pub_req.wait_for_all_acked(Duration(seconds=20))
    # a valid request from a given start: planned on the last good map (map 1), not on a bad one
    pub_req.publish(request_msg(PlanRequest(request_id=20, min_map_stamp_ns=0, start_xyz_m=(0.40, -0.10, 0.06))))
    g.wait_for(lambda: any(answer_from_msg(s).request_id == 20 for s in status), 20, "the answer to request 20")
    answer = [s for s in status if answer_from_msg(s).request_id == 20][0]
    assert answer.message == "ok", _status_values(answer)
    g_xy = np.array([goals[-1].pose.position.x, goals[-1].pose.position.y])
    assert np.linalg.norm(g_xy - CENTRE) == pytest.approx(RADIUS + 0.02, abs=1e-6)  # on the good map's circle
    # a request without a start plans from the measured tip: the bad tips were not taken
    pub_req.publish(request_msg(PlanRequest(request_id=21, min_map_stamp_ns=0)))
    g.observe(1.0, "no plan without a valid tip pose")
    assert not any(answer_from_msg(s).request_id == 21 for s in status)
    valid_tip = pose_msg([0.40, -0.10, 0.06])

    def tip_again():
        pub_tip.publish(valid_tip)
        return any(answer_from_msg(s).request_id == 21 for s in status)

    g.wait_for(tip_again, 20, "the answer to request 21")
    # every bad input counted (read from a later answer: inputs on other topics may be taken after request 20)
    answer = [s for s in status if answer_from_msg(s).request_id == 21][0]
    assert int(_status_values(answer)["invalid_inputs"]) == n_bad, (_status_values(answer), n_bad)
    path = [p for p in paths if p.header.stamp.nanosec == 21][0]
    start = path.poses[0].pose.position
    np.testing.assert_allclose([start.x, start.y, start.z], [0.40, -0.10, 0.06], atol=1e-9)
    assert g.procs["planner"].alive()


def test_commander_rejects_bad_goals_and_paths_and_runs_the_next_valid_one(ros_graph):
    """Dry run (no rig): a valid touch is planned from home and published on ~/planned_trajectory."""
    g = ros_graph
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    planned = g.collect("/arm_commander/planned_trajectory", JointTrajectory, qos.EVENTS)
    g.start("arm", ["arm_commander", "--ros-args", "--params-file", str(ARM_YAML), "-p", "move_to_start:=false",
                    "-p", "dry_run:=true"])
    goal_pub = g.node.create_publisher(PoseStamped, topics.GOAL, qos.EVENTS)
    path_pub = g.node.create_publisher(Path, topics.PATH, qos.EVENTS)
    g.wait_for(lambda: goal_pub.get_subscription_count() and path_pub.get_subscription_count()
               and done.publishers and planned.publishers, 30, "the commander")
    pre, d = np.array([0.40, 0.20, 0.06]), np.array([0.0, 1.0, 0.0])
    path = np.array([[0.50, 0.0, 0.35], [0.42, 0.12, 0.10], pre])
    cases = {}
    goal, p = goal_and_path([np.nan, 0.2, 0.06], d, path, 101)
    cases[101] = (goal, p, "not finite")
    goal, p = goal_and_path(pre, d, path, 102)
    goal.pose.orientation.x = goal.pose.orientation.y = goal.pose.orientation.z = goal.pose.orientation.w = 0.0
    cases[102] = (goal, p, "quaternion")
    goal, p = goal_and_path(pre, d, path, 103)
    p.poses[1].pose.position.y = float("inf")
    cases[103] = (goal, p, "not finite")
    cases[104] = (*goal_and_path(pre, d, path, 104, frame_id="base_link"), "frame")
    goal, p = goal_and_path(pre, d, path, 105)
    p.header.frame_id = "base_link"
    cases[105] = (goal, p, "frame")
    for stamp, (goal, p, _) in cases.items():
        goal_pub.publish(goal)
        path_pub.publish(p)
    g.wait_for(lambda: len(done) >= len(cases), 20, "a report for every bad goal")
    by_stamp = {int(done_values(m)["goal_stamp_ns"]): m for m in done}
    for stamp, (_, _, why) in cases.items():
        m = by_stamp[stamp]
        assert m.message == "unreachable" and why in done_values(m)["reason"], (stamp, done_values(m))
    assert planned == []
    assert g.procs["arm"].log().count("invalid goal") == len(cases)
    goal, p = goal_and_path(pre, d, path, 200)
    goal_pub.publish(goal)
    path_pub.publish(p)
    g.wait_for(lambda: len(planned) >= 3 and 200 in {int(done_values(m)["goal_stamp_ns"]) for m in done}, 20,
               "the valid goal planned")
    assert "dry_run" in done_values([m for m in done if done_values(m)["goal_stamp_ns"] == "200"][0])["reason"]


def test_viz_ignores_bad_contacts_maps_and_joint_states_and_draws_the_valid_contact(ros_graph):
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    g = ros_graph
    g.start("viz", ["viz", "--ros-args", "-p", "arm_period_s:=0.0"])
    markers = g.collect("/tactile/contact_markers", MarkerArray, qos.LATCHED)
    arm = g.collect("/viz/arm", MarkerArray, qos.SENSOR)
    contacts_pub = g.node.create_publisher(PointCloud2, topics.CONTACTS, qos.OBSERVATIONS)
    map_pub = g.node.create_publisher(PointCloud2, topics.VARIANCE_MAP, qos.MAP)
    js_pub = g.node.create_publisher(JointState, topics.JOINT_STATES, qos.STATE)
    g.wait_for(lambda: contacts_pub.get_subscription_count() and map_pub.get_subscription_count()
               and js_pub.get_subscription_count() and markers.publishers and arm.publishers, 30, "the viz node")
    nan = _contact(0.3)
    nan["x"] = np.nan
    flabel = np.zeros(1, dtype=[(n, np.float64) for n in fields.CONTACT_DTYPE.names])
    for n in fields.CONTACT_DTYPE.names:
        flabel[n] = _contact(0.9)[n]
    flabel["label"] = np.nan
    bad = [to_pointcloud2(nan, "world"), to_pointcloud2(flabel, "world"), to_pointcloud2(_contact(1.5), "base_link"),
           *_broken_clouds(to_pointcloud2(_contact(), "world")).values()]
    for msg in bad:
        contacts_pub.publish(msg)
    one_node = sphere_map(64, 2, seed=3)[:1]  # a single lattice node: not a grid
    map_pub.publish(to_pointcloud2(one_node, "world"))
    names = [f"panda_joint{i}" for i in range(1, 8)]
    for positions in ([float("nan")] * 7, [0.0] * 5):
        js_pub.publish(JointState(name=names, position=positions))
    valid = _contact(2.0)
    contacts_pub.publish(to_pointcloud2(valid, "world", Time(sec=1)))
    js_pub.publish(JointState(name=names, position=[0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854]))

    def drawn(msg):
        return [(p.x, p.y, p.z) for m in msg.markers if m.ns in ("contacts", "free_space") for p in m.points]

    def valid_drawn():
        return arm and [m for m in markers if np.any(np.all(np.isclose(drawn(m), fields.xyz(valid)), axis=1))]

    g.wait_for(valid_drawn, 20, "the valid contact drawn and the arm")
    np.testing.assert_allclose(drawn(valid_drawn()[0]), fields.xyz(valid), atol=1e-12)  # nothing else drawn
    assert all(np.isfinite([p.x for m in a.markers for p in m.points]).all() for a in arm)
    assert g.procs["viz"].alive()
