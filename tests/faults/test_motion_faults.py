"""Motion faults on the simulated rig: every trajectory sent to the controller is checked by a monitor.

Faults: goals outside the safety box (the goal itself, an approach below the
table), an IK-unreachable goal inside the box, an e-stop during an approach,
stale or invalid /joint_states. The monitor (tactile_driver.trajectory_monitor,
fed by fault_helpers.TrajectoryWatch on the test's node) rebuilds each
published trajectory's spline with scipy and checks joint position, velocity
and acceleration limits, the tip (forward kinematics) against the box, and
that it starts at the measured state; no violation may ever be published.
Nodes: sim_rig (sensor off) and arm_commander only.
"""

import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from tactile_common import qos, topics

from fault_helpers import ARM_YAML, TrajectoryWatch, commander_monitor, done_values, goal_and_path

pytestmark = pytest.mark.graph

ARM = ["arm_commander", "--ros-args", "--params-file", str(ARM_YAML), "-p", "move_to_start:=false"]
HOME = [0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854]  # tip at (0.50, 0.00, 0.35)
NAMES = [f"panda_joint{i}" for i in range(1, 8)]
PRE, DIRECTION = np.array([0.40, 0.20, 0.06]), np.array([0.0, 1.0, 0.0])
PATH = np.array([[0.50, 0.0, 0.35], [0.42, 0.12, 0.10], PRE])
RTF = 2.0


class Touches:
    def __init__(self, graph):
        self.goal = graph.node.create_publisher(PoseStamped, topics.GOAL, qos.EVENTS)
        self.path = graph.node.create_publisher(Path, topics.PATH, qos.EVENTS)
        graph.wait_for(lambda: self.goal.get_subscription_count() and self.path.get_subscription_count(), 30,
                       "commander subscriptions")

    def send(self, stamp_ns, pre=PRE, direction=DIRECTION, path=PATH):
        goal, path_msg = goal_and_path(pre, direction, path, stamp_ns)
        self.goal.publish(goal)
        self.path.publish(path_msg)


def _start_rig_and_commander(g, *extra):
    g.start("sim", ["sim_rig", "--ros-args", "-p", "sensor_enabled:=false", "-p", f"real_time_factor:={RTF}"])
    g.start("arm", [*ARM, "-p", "use_sim_time:=true", "-p", "watchdog_timeout_s:=2.0", *extra])


def _xyz(pose: PoseStamped) -> np.ndarray:
    p = pose.pose.position
    return np.array([p.x, p.y, p.z])


def test_goals_outside_the_box_or_out_of_reach_move_nothing(ros_graph):
    g = ros_graph
    watch = TrajectoryWatch(g, commander_monitor())
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    _start_rig_and_commander(g)
    g.wait_for(lambda: watch.states > 5 and watch.publishers and done.publishers, 30,
               "joint states and the commander's writers")
    touches = Touches(g)
    cases = [  # (pre-touch, approach direction, path, what the reason names)
        (np.array([0.85, 0.0, 0.10]), np.array([1.0, 0.0, 0.0]), [[0.5, 0.0, 0.35], [0.85, 0.0, 0.10]], "box"),
        (np.array([0.50, 0.0, 0.03]), np.array([0.0, 0.0, -1.0]), [[0.5, 0.0, 0.35], [0.50, 0.0, 0.03]], "box"),
        (np.array([0.70, 0.0, 0.55]), np.array([0.0, 0.0, -1.0]), [[0.5, 0.0, 0.35], [0.70, 0.0, 0.55]],
         "unreachable"),
    ]
    for i, (pre, d, path, why) in enumerate(cases):
        touches.send(100 + i, pre, d, np.array(path))
        g.wait_for(lambda: len(done) > i, 20, f"the report of bad goal {i}")
        assert done[i].message == "unreachable", done_values(done[i])
        assert why in done_values(done[i])["reason"], done_values(done[i])
    g.observe(0.5, "no trajectory for a rejected goal")
    assert watch.sent == []
    # a valid touch afterwards runs: path, approach, retract (free space: the sensor is off)
    touches.send(200)
    g.wait_for(lambda: len(done) > 3, 40, "the valid touch's report")
    assert done[3].message == "free_space", done_values(done[3])
    assert len(watch.motions()) == 3
    watch.assert_safe()


def test_estop_during_an_approach_then_a_touch_from_where_the_arm_stopped(ros_graph):
    g = ros_graph
    watch = TrajectoryWatch(g, commander_monitor())
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    _start_rig_and_commander(g)
    estop = g.node.create_publisher(Bool, topics.ESTOP, qos.LATCHED)
    g.wait_for(lambda: len(poses) > 5 and watch.states > 5 and watch.publishers and done.publishers, 30,
               "fingertip poses and the commander's writers")
    touches = Touches(g)
    touches.send(7)
    g.wait_for(lambda: len(watch.sent) >= 2, 40, "the approach trajectory")
    g.wait_for(lambda: np.dot(_xyz(poses[-1]) - PRE, DIRECTION) > 0.002, 10, "the tip to move along the approach")
    estop.publish(Bool(data=True))
    g.wait_for(lambda: done and len(watch.sent) >= 3, 10, "touch_done and the stop")
    assert done[0].message == "aborted" and "e-stop" in done_values(done[0])["reason"]
    assert watch.sent[2].points == []  # the stop: an empty trajectory
    n_poses = len(poses)
    g.wait_for(lambda: len(poses) > n_poses + 10, 10, "fingertip poses after the stop")
    stopped_at = _xyz(poses[-1])
    estop.publish(Bool(data=False))
    g.wait_for(lambda: "e-stop released" in g.procs["arm"].log(), 10, "the commander to take the release")
    # The next touch starts where the arm stopped (mid-approach), not at the planned pre-touch point.
    n_before = len(watch.motions())
    touches.send(9)
    g.wait_for(lambda: len(done) >= 2, 60, "the next touch's report")
    assert done[1].message == "free_space", done_values(done[1])
    first = watch.motions()[n_before]
    tip0 = watch.monitor.model.fk(np.array(first.points[0].positions))[0]
    assert np.linalg.norm(tip0 - stopped_at) < 0.002, (tip0, stopped_at)
    watch.assert_safe()
    assert watch.monitor.checked == len(watch.sent)


def test_stale_or_invalid_joint_states_stop_motion_and_the_next_plan_starts_at_the_measured_state(ros_graph):
    """No rig: the test is the controller that never moves; it switches to invalid joint states mid-path."""
    g = ros_graph
    watch = TrajectoryWatch(g, commander_monitor())
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    js_pub = g.node.create_publisher(JointState, topics.JOINT_STATES, qos.STATE)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    nan = list(HOME)
    nan[3] = float("nan")
    invalid = [JointState(name=NAMES, position=nan),  # not finite
               JointState(name=NAMES[:6], position=HOME[:6]),  # a joint missing
               JointState(name=NAMES, position=HOME[:5]),  # sizes differ
               JointState(name=NAMES, position=[float("inf")] * 7)]
    feed = {"mode": "valid", "i": 0}

    def publish():
        if feed["mode"] == "valid":
            js_pub.publish(JointState(name=NAMES, position=HOME))
        elif feed["mode"] == "invalid":
            feed["i"] += 1
            js_pub.publish(invalid[feed["i"] % len(invalid)])

    g.node.create_timer(0.01, publish)
    g.start("arm", [*ARM, "-p", "watchdog_timeout_s:=1.0"])  # well above a starved process's pauses (load ~25)
    g.wait_for(lambda: js_pub.get_subscription_count() and watch.states > 5 and watch.publishers and done.publishers,
               30, "commander")
    g.wait_for(lambda: "arm_commander ready" in g.procs["arm"].log(), 20, "the commander")
    # The commander publishes a fingertip pose for every joint state it takes: once they flow, its
    # watchdog is fed and a goal is planned (not refused for "no recent joint state").
    n_poses = len(poses)
    g.wait_for(lambda: len(poses) > n_poses + 5, 20, "the commander's fingertip poses")
    touches = Touches(g)
    touches.send(11)
    g.wait_for(lambda: watch.sent, 20, "the path trajectory")
    feed["mode"] = "invalid"
    t_switch = time.monotonic()
    g.wait_for(lambda: len(watch.sent) >= 2, 5, "the stop")
    assert watch.sent[1].points == []
    assert time.monotonic() - t_switch < 3.0
    g.wait_for(lambda: done, 5, "touch_done")
    assert done[0].message == "aborted" and "stale" in done_values(done[0])["reason"]
    # While only invalid states arrive, a goal is refused without motion.
    touches.send(12)
    g.wait_for(lambda: len(done) >= 2, 10, "the refused touch")
    assert done[1].message in ("aborted", "unreachable"), done_values(done[1])
    assert len(watch.sent) == 2
    assert "joint state without finite positions" in g.procs["arm"].log()
    # Valid states again: the next touch plans from the measured state (HOME), which the monitor checks.
    n_poses = len(poses)
    feed["mode"] = "valid"
    # the commander publishes a fingertip pose per valid joint state it takes
    g.wait_for(lambda: len(poses) > n_poses + 20, 10, "the commander to take valid joint states")
    touches.send(13)
    g.wait_for(lambda: len(watch.sent) >= 3, 20, "motion again")
    np.testing.assert_allclose(watch.sent[2].points[0].positions, HOME, atol=1e-9)
    watch.assert_safe()


def test_malformed_contacts_during_an_approach_do_not_stop_it(ros_graph):
    from sensor_msgs.msg import PointCloud2

    from tactile_common import fields
    from tactile_common.pointcloud import to_pointcloud2
    from tactile_common.stamps import time_from_ns

    g = ros_graph
    watch = TrajectoryWatch(g, commander_monitor())
    done = g.collect(topics.TOUCH_DONE, DiagnosticStatus, qos.EVENTS)
    poses = g.collect(topics.FINGERTIP_POSE, PoseStamped, qos.SENSOR)
    contacts = g.node.create_publisher(PointCloud2, topics.CONTACTS, qos.OBSERVATIONS)
    _start_rig_and_commander(g)
    g.wait_for(lambda: len(poses) > 5 and watch.states > 5 and watch.publishers and done.publishers
               and contacts.get_subscription_count(),
               30, "fingertip poses, the commander's writers and its contact subscription")
    Touches(g).send(7)
    g.wait_for(lambda: len(watch.sent) >= 2, 40, "the approach trajectory")
    g.wait_for(lambda: np.dot(_xyz(poses[-1]) - PRE, DIRECTION) > 0.002, 10, "the tip to move along the approach")
    now_ns = g.node.get_clock().now().nanoseconds  # newer than the approach's start on any clock of this test
    nan, other = np.zeros(1, fields.CONTACT_DTYPE), np.zeros(1, fields.CONTACT_DTYPE)
    nan["x"], nan["label"] = np.nan, fields.LABEL_CONTACT
    other["x"], other["y"], other["z"], other["label"] = *(PRE + 0.01 * DIRECTION), fields.LABEL_CONTACT
    contacts.publish(to_pointcloud2(nan, topics.WORLD_FRAME, time_from_ns(now_ns + 10**12)))
    contacts.publish(to_pointcloud2(other, "base_link", time_from_ns(now_ns + 10**12)))
    g.wait_for(lambda: done, 30, "the touch's report")
    assert done[0].message == "free_space", done_values(done[0])
    watch.assert_safe()
