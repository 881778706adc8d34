"""soc_planner as a process: synthetic circle map + tip pose + request → goal and path with equal stamps."""

from pathlib import Path as FsPath

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.duration import Duration
from std_msgs.msg import Header

from tactile_common import stamps
from tactile_common.cycle import PlanRequest, TouchOutcome, TouchReport
from tactile_common.cycle_msgs import answer_from_msg, report_msg, request_msg
from tactile_common import qos, topics
from tactile_common.pointcloud import to_pointcloud2
from tactile_planner.synthetic import sphere_map

pytestmark = pytest.mark.graph

CONFIG = FsPath(__file__).resolve().parents[2] / "src/tactile_planner/config/soc_planner.yaml"
CENTER = np.array([0.5, 0.0])
RADIUS = 0.05
OLD_RADIUS = 0.03  # the too-old map's circle: a goal planned on it misses RADIUS


def _quat_x_axis(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)])


def test_goal_and_path_for_a_request(ros_graph):
    ros_graph.start("planner", ["soc_planner", "--ros-args", "--params-file", str(CONFIG)])
    node = ros_graph.node
    goals = ros_graph.collect(topics.GOAL, PoseStamped, qos.EVENTS)
    paths = ros_graph.collect(topics.PATH, Path, qos.EVENTS)
    status = ros_graph.collect("/planner/status", DiagnosticStatus, qos.EVENTS)
    pub_map = node.create_publisher(type(to_pointcloud2(sphere_map(8, 2)[:0], "world")), topics.VARIANCE_MAP, qos.MAP)
    pub_tip = node.create_publisher(PoseStamped, topics.FINGERTIP_POSE, qos.SENSOR)
    pub_req = node.create_publisher(DiagnosticStatus, "/planner/request", qos.EVENTS)
    pub_done = node.create_publisher(DiagnosticStatus, topics.TOUCH_DONE, qos.EVENTS)

    tip = PoseStamped()
    tip.header.frame_id = "world"
    tip.pose.position.x, tip.pose.position.y, tip.pose.position.z = 0.40, -0.10, 0.06
    # request before the map exists: the planner must wait for a map with stamp >= 5 s
    ros_graph.wait_for(lambda: pub_req.get_subscription_count() > 0 and pub_tip.get_subscription_count() > 0
                       and goals.publishers and paths.publishers and status.publishers,
                       20, "planner subscriptions and writers")
    pub_req.publish(request_msg(PlanRequest(request_id=7, min_map_stamp_ns=5_000_000_000)))
    old = sphere_map(64, 2, radius_m=OLD_RADIUS, seed=3)
    pub_map.publish(to_pointcloud2(old, "world", stamp=Time(sec=1)))  # too old
    ros_graph.wait_for(lambda: pub_map.get_subscription_count() > 0, 20, "map subscription")
    # The request and the too-old map delivered (the map before the valid one replaces it in the
    # latched history, depth 1) and tip poses flowing: everything but a new-enough map. No goal.
    assert pub_req.wait_for_all_acked(Duration(seconds=20)) and pub_map.wait_for_all_acked(Duration(seconds=20))
    node.create_timer(0.05, lambda: pub_tip.publish(tip))
    ros_graph.observe(1.0, "no goal on a too-old map")
    assert not goals
    pub_map.publish(to_pointcloud2(sphere_map(64, 2, seed=3), "world", stamp=Time(sec=5)))

    def tip_again():
        pub_tip.publish(tip)
        return goals and paths and status

    ros_graph.wait_for(tip_again, 20, "goal and path")
    goal, path = goals[0], paths[0]
    assert goal.header.stamp == path.header.stamp
    assert stamps.stamp_ns(goal.header.stamp) == 7  # the goal's id is the request it answers
    assert answer_from_msg(status[-1]).request_id == 7
    assert status and status[-1].message == "ok"
    g = np.array([goal.pose.position.x, goal.pose.position.y, goal.pose.position.z])
    # pre-touch point on the analytic circle's offset: radius + standoff + tip radius, in the plane
    assert np.linalg.norm(g[:2] - CENTER) == pytest.approx(RADIUS + 0.02, abs=1e-6)
    assert g[2] == pytest.approx(0.06)
    x_axis = _quat_x_axis(goal.pose.orientation)
    inward = np.append(CENTER - g[:2], 0.0)
    np.testing.assert_allclose(x_axis, inward / np.linalg.norm(inward), atol=1e-6)
    pts = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in path.poses])
    np.testing.assert_allclose(pts[0], [0.40, -0.10, 0.06], atol=1e-9)
    np.testing.assert_allclose(pts[-1], g, atol=1e-9)

    # the commander reports that goal unreachable: the next plan avoids its target
    done = DiagnosticStatus(name="touch", message="unreachable", level=DiagnosticStatus.WARN)
    stamp_ns = goal.header.stamp.sec * 1_000_000_000 + goal.header.stamp.nanosec
    done.values = [KeyValue(key="goal_stamp_ns", value=str(stamp_ns))]
    n_status = len(status)
    ros_graph.wait_for(lambda: pub_done.get_subscription_count() > 0, 10, "touch_done subscription")
    pub_done.publish(done)
    ros_graph.wait_for(lambda: "excluding candidates" in ros_graph.procs["planner"].log(), 10, "exclusion logged")
    pub_req.publish(request_msg(PlanRequest(request_id=8, min_map_stamp_ns=5_000_000_000)))
    ros_graph.wait_for(lambda: len(goals) >= 2 and len(status) > n_status, 20, "second goal")
    g2 = np.array([goals[1].pose.position.x, goals[1].pose.position.y])
    assert np.linalg.norm(g2 - g[:2]) > 0.02

    # the same request again (a re-send, or history after a restart): the same answer, not a new plan
    n_goals = len(goals)
    pub_req.publish(request_msg(PlanRequest(request_id=8, min_map_stamp_ns=5_000_000_000)))
    ros_graph.wait_for(lambda: len(goals) > n_goals, 20, "the stored answer again")
    assert goals[-1].header.stamp == goals[1].header.stamp and goals[-1].pose == goals[1].pose
    # an older request than one already seen is superseded: no answer
    pub_req.publish(request_msg(PlanRequest(request_id=3, min_map_stamp_ns=0)))
    pub_req.publish(request_msg(PlanRequest(request_id=9, min_map_stamp_ns=0)))
    ros_graph.wait_for(lambda: any(answer_from_msg(s).request_id == 9 for s in status), 20, "answer to request 9")
    assert not any(answer_from_msg(s).request_id == 3 for s in status)


def test_a_restarted_planner_answers_the_resent_request_whose_touch_already_ended(ros_graph):
    """The old planner's goal went out and was run, its answer died with it: the touch has ended but the
    explorer still waits. The request handed over by the durable history is skipped (its touch ended);
    the explorer's re-send of it is answered, from the request's own start."""
    ros_graph.start("planner", ["soc_planner", "--ros-args", "--params-file", str(CONFIG)])
    node = ros_graph.node
    status = ros_graph.collect("/planner/status", DiagnosticStatus, qos.EVENTS)
    pub_map = node.create_publisher(type(to_pointcloud2(sphere_map(8, 2)[:0], "world")), topics.VARIANCE_MAP, qos.MAP)
    pub_req = node.create_publisher(DiagnosticStatus, "/planner/request", qos.EVENTS)
    pub_done = node.create_publisher(DiagnosticStatus, topics.TOUCH_DONE, qos.EVENTS)
    ros_graph.wait_for(lambda: all(p.get_subscription_count() > 0 for p in (pub_map, pub_req, pub_done))
                       and status.publishers, 20, "planner subscriptions and writers")
    pub_map.publish(to_pointcloud2(sphere_map(64, 2, seed=3), "world", stamp=Time(sec=5)))
    pub_done.publish(report_msg(TouchReport(7, TouchOutcome.CONTACT, "", 6_000_000_000, 0.1, 2.0)))
    assert pub_map.wait_for_all_acked(Duration(seconds=20)) and pub_done.wait_for_all_acked(Duration(seconds=20))
    request = PlanRequest(request_id=7, min_map_stamp_ns=5_000_000_000, start_xyz_m=(0.40, -0.10, 0.06),
                          visited_xyz_m=(), excluded_xyz_m=())
    pub_req.publish(request_msg(request))  # as handed over: skipped
    assert pub_req.wait_for_all_acked(Duration(seconds=20))
    ros_graph.observe(1.0, "no answer to a request whose touch has ended")
    assert not status
    pub_req.publish(request_msg(request))  # the explorer's re-send: answered
    ros_graph.wait_for(lambda: status, 20, "the answer to the re-sent request")
    answer = answer_from_msg(status[0])
    assert answer.request_id == 7 and answer.ok, answer
