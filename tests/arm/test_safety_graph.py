"""Safety on the graph: e-stop during an approach, stale joint states, dry run (arm_commander process)."""

import time
from pathlib import Path as FsPath

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from tactile_common import qos, topics
from tactile_common.testing import Received

from graph_helpers import done_values, goal_and_path

pytestmark = pytest.mark.graph

ROOT = FsPath(__file__).resolve().parents[2]
ARM_PARAMS = ["--params-file", str(ROOT / "src/tactile_driver/config/arm_commander.yaml"), "-p", "move_to_start:=false"]
HOME = [0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854]
NAMES = [f"panda_joint{i}" for i in range(1, 8)]
PRE, DIRECTION = np.array([0.40, 0.20, 0.06]), np.array([0.0, 1.0, 0.0])
PATH = np.array([[0.50, 0.0, 0.35], [0.42, 0.12, 0.10], PRE])
CONTROL_PERIOD_S = 0.01
SLACK_S = 0.15  # process scheduling + DDS on a loaded 2-core machine


class TouchPublisher:
    def __init__(self, graph):
        self.goal = graph.node.create_publisher(PoseStamped, topics.GOAL, qos.EVENTS)
        self.path = graph.node.create_publisher(Path, topics.PATH, qos.EVENTS)
        graph.wait_for(lambda: self.goal.get_subscription_count() and self.path.get_subscription_count(), 20,
                       "commander subscriptions")

    def send(self, stamp_ns, pre=PRE, path=PATH):
        goal, path_msg = goal_and_path(pre, DIRECTION, path, stamp_ns)
        self.goal.publish(goal)
        self.path.publish(path_msg)


def _timed(graph, topic, msg_type, profile):
    """Messages with their wall arrival times."""
    out = Received()
    out.subscription = graph.node.create_subscription(msg_type, topic, lambda m: out.append((time.monotonic(), m)),
                                                      profile)
    return out


def _xyz(pose: PoseStamped) -> np.ndarray:
    p = pose.pose.position
    return np.array([p.x, p.y, p.z])


def test_dry_run_plans_and_publishes_no_trajectory(ros_graph):
    g = ros_graph
    sent = g.collect(topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    planned = g.collect("/arm_commander/planned_trajectory", JointTrajectory, qos.EVENTS)
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    g.start("arm", ["arm_commander", "--ros-args", *ARM_PARAMS, "-p", "dry_run:=true"])
    g.wait_for(lambda: planned.publishers and done.publishers, 20, "the commander's writers")
    TouchPublisher(g).send(5)
    # touch_done and the planned trajectories travel on different topics: wait for both.
    g.wait_for(lambda: done and len(planned) >= 3, 20, "touch_done and three planned trajectories")
    assert done[0].message == "aborted" and "dry_run" in done_values(done[0])["reason"]
    assert len(planned) == 3 and all(len(m.points) > 1 for m in planned)  # path, approach, retract
    # No joint states: planned from home, each motion from the end of the previous one.
    np.testing.assert_allclose(planned[0].points[0].positions, HOME, atol=1e-9)
    for a, b in zip(planned[:-1], planned[1:]):
        np.testing.assert_allclose(b.points[0].positions, a.points[-1].positions, atol=1e-9)
    np.testing.assert_allclose(planned[2].points[-1].positions, planned[1].points[0].positions, atol=2e-3)
    g.observe(0.3, "no trajectory for the controller")
    assert sent == []


def test_estop_during_approach_stops_the_rig_within_a_control_period(ros_graph):
    g = ros_graph
    sent = _timed(g, topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    states = _timed(g, topics.JOINT_STATES, JointState, qos.SENSOR)
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    rtf = 2.0
    g.start("sim", ["sim_rig", "--ros-args", "-p", "sensor_enabled:=false", "-p", f"real_time_factor:={rtf}"])
    g.start("arm", ["arm_commander", "--ros-args", *ARM_PARAMS, "-p", "use_sim_time:=true", "-p", "watchdog_timeout_s:=2.0"])
    estop = g.node.create_publisher(Bool, topics.ESTOP, qos.LATCHED)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    g.wait_for(lambda: len(poses) > 5 and len(states) > 5 and sent.publishers and done.publishers, 30,
               "joint states, fingertip poses and the commander's writers")
    TouchPublisher(g).send(7)
    g.wait_for(lambda: len(sent) >= 2, 40, "the approach trajectory")  # path, then approach
    # the approach (2 s of simulated time) is under way: the tip has gone 2 mm past the pre-touch point
    g.wait_for(lambda: np.dot(_xyz(poses[-1]) - PRE, DIRECTION) > 0.002, 10, "the tip to move along the approach")
    estop.publish(Bool(data=True))
    g.wait_for(lambda: len(sent) >= 3, 5, "the stop")
    t_stop, stop = sent[2]
    assert stop.points == []  # ros2_control: an empty trajectory stops and holds
    g.wait_for(lambda: done, 5, "touch_done")
    assert done[0].message == "aborted" and "e-stop" in done_values(done[0])["reason"]
    assert done[0].level == DiagnosticStatus.ERROR
    g.wait_for(lambda: states[-1][0] > t_stop + 0.5, 5, "joint states after the stop")
    after = np.array([m.position for t, m in states if t > t_stop + CONTROL_PERIOD_S / rtf + SLACK_S])
    assert len(after) > 10
    np.testing.assert_array_equal(after, after[:1].repeat(len(after), 0))  # no motion at all
    # While engaged, a new goal is refused without motion; after release it runs.
    TouchPublisher(g).send(8)
    g.wait_for(lambda: len(done) >= 2, 10, "refused touch")
    assert done[1].message == "aborted" and "e-stop" in done_values(done[1])["reason"]
    assert len(sent) == 3
    estop.publish(Bool(data=False))
    # no topic says the release was taken; the commander's log does
    g.wait_for(lambda: "e-stop released" in g.procs["arm"].log(), 10, "the commander to take the release")
    TouchPublisher(g).send(9)
    g.wait_for(lambda: len(sent) >= 4 and sent[3][1].points, 20, "motion after release")


def test_stale_joint_states_stop_motion(ros_graph):
    g = ros_graph
    sent = _timed(g, topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    js_pub = g.node.create_publisher(JointState, topics.JOINT_STATES, qos.SENSOR)
    js = JointState(name=NAMES, position=HOME)
    feeding = {"on": True}
    g.node.create_timer(0.01, lambda: feeding["on"] and js_pub.publish(js))
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    timeout_s = 0.3
    g.start("arm", ["arm_commander", "--ros-args", *ARM_PARAMS, "-p", f"watchdog_timeout_s:={timeout_s}"])
    g.wait_for(lambda: js_pub.get_subscription_count() and sent.publishers and done.publishers, 20, "commander")
    g.wait_for(lambda: len(poses) >= 5, 10, "fingertip poses: the commander has joint states")
    TouchPublisher(g).send(11)
    g.wait_for(lambda: sent, 20, "the path trajectory")
    feeding["on"] = False
    t_last = time.monotonic()
    g.wait_for(lambda: len(sent) >= 2, 5, "the stop")
    t_stop, stop = sent[1]
    assert stop.points == []
    assert t_stop - t_last <= timeout_s + CONTROL_PERIOD_S + SLACK_S
    g.wait_for(lambda: done, 5, "touch_done")
    assert done[0].message == "aborted" and "stale" in done_values(done[0])["reason"]


def test_move_to_start_is_planned_again_once_stalled_joint_states_flow(ros_graph):
    """The start-up move ends on a joint-state stall (stop sent), then runs again when they flow."""
    g = ros_graph
    sent = _timed(g, topics.JOINT_TRAJECTORY, JointTrajectory, qos.COMMANDS)
    js_pub = g.node.create_publisher(JointState, topics.JOINT_STATES, qos.SENSOR)
    js = JointState(name=NAMES, position=HOME)  # a controller that never moves: the move stays in progress
    feeding = {"on": True}
    g.node.create_timer(0.01, lambda: feeding["on"] and js_pub.publish(js))
    g.start("arm", ["arm_commander", "--ros-args", "--params-file",
                    str(ROOT / "src/tactile_driver/config/arm_commander.yaml"), "-p", "watchdog_timeout_s:=0.3"])
    g.wait_for(lambda: sent, 20, "the move to the start position")
    assert sent[0][1].points
    feeding["on"] = False
    g.wait_for(lambda: len(sent) >= 2, 5, "the stop")
    assert sent[1][1].points == []
    # Nothing is sent while the joint states are missing, however long that lasts.
    g.observe(1.0, "a stall longer than the watchdog")
    assert len(sent) == 2
    feeding["on"] = True
    g.wait_for(lambda: len(sent) >= 3, 5, "the move planned again")
    again = sent[2][1]
    assert again.points and np.allclose(again.points[-1].positions, sent[0][1].points[-1].positions, atol=1e-6)
