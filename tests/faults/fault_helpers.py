"""Helpers of the fault tests: the trajectory watch (a subscriber on the test's node), messages, log counts."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import yaml
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from tactile_common import qos, topics
from tactile_common.stamps import time_from_ns
from tactile_driver.arm_msgs import joint_positions, pose_stamped
from tactile_driver.kinematics import ArmModel
from tactile_driver.trajectory_monitor import TrajectoryMonitor, Violation

ROOT = Path(__file__).resolve().parents[2]
ARM_YAML = ROOT / "src/tactile_driver/config/arm_commander.yaml"


def commander_monitor(**kwargs) -> TrajectoryMonitor:
    """A monitor with the limits and the box of the commander's parameter file (the box grown by its
    ``ik_tol_m``, as the commander checks IK waypoints)."""
    p = yaml.safe_load(ARM_YAML.read_text())["arm_commander"]["ros__parameters"]
    kwargs.setdefault("box_slack_m", p["ik_tol_m"])
    model = ArmModel(p["urdf_path"], p["joint_names"], p["flange_frame"], p["tip_offset_m"])
    return TrajectoryMonitor.from_params(model, p["max_joint_velocity_rad_s"], p["max_joint_acceleration_rad_s2"],
                                         p["box_x_m"], p["box_y_m"], p["box_z_m"], p["table_z_m"],
                                         p["table_margin_m"], **kwargs)


class TrajectoryWatch:
    """Checks every trajectory published for the controller: limits and box at once, its start later.

    The start must be a state the arm was in when the trajectory arrived (the simulated controller
    jumps to a first point at time 0). Which joint state this process took last is not that state on
    a loaded machine (the executor may take the trajectory before joint states already queued), so
    the start is compared, in :meth:`assert_safe`, with every state measured within
    ``start_window_s`` of the trajectory's arrival (steady clock).

    Attributes:
        sent: every JointTrajectory received (stops included).
        monitor: the :class:`TrajectoryMonitor`; ``monitor.violations`` must stay empty.
    """

    def __init__(self, graph, monitor: TrajectoryMonitor, start_window_s: float = 1.0) -> None:
        self.monitor = monitor
        self.names = list(monitor.model.joint_names)
        self.start_window_s = float(start_window_s)
        self.q_now = None
        self.sent: list[JointTrajectory] = []
        self.states = 0
        self._history: list = []  # (arrival s, q) of every joint state
        self._starts: list = []  # (arrival s, first point) of every motion
        node = graph.node
        self.subscription = node.create_subscription(JointTrajectory, topics.JOINT_TRAJECTORY, self._on_traj,
                                                     qos.COMMANDS)
        node.create_subscription(JointState, topics.JOINT_STATES, self._on_state, qos.STATE)

    @property
    def publishers(self) -> int:
        return self.subscription.get_publisher_count()

    def motions(self) -> list[JointTrajectory]:
        return [m for m in self.sent if m.points]

    def _on_state(self, msg: JointState) -> None:
        q = joint_positions(msg, self.names)
        if q is not None:
            self.q_now, self.states = q, self.states + 1
            self._history.append((time.monotonic(), q))

    def _on_traj(self, msg: JointTrajectory) -> None:
        self.sent.append(msg)
        t = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points]
        q = [list(p.positions) for p in msg.points]
        qd = [list(p.velocities) for p in msg.points]
        if not any(qd):
            qd = None
        self.monitor.check(msg.joint_names, t, q, qd)
        if msg.points and t[0] == 0.0 and sorted(msg.joint_names) == sorted(self.names):
            order = [list(msg.joint_names).index(j) for j in self.names]
            self._starts.append((time.monotonic(), np.asarray(q[0], dtype=float)[order]))

    def start_violations(self) -> list[Violation]:
        """Motions whose first point is no state measured within the window around their arrival."""
        out = []
        for i, (t, q0) in enumerate(self._starts):
            near = [q for s, q in self._history if abs(s - t) <= self.start_window_s]
            jump = min((float(np.abs(q - q0).max()) for q in near), default=float("inf"))
            if jump > self.monitor.start_tolerance_rad:
                gaps = [s - t for s, _ in self._history]
                nearest = min(gaps, key=abs) if gaps else float("nan")
                out.append(Violation("start", "", 0.0, jump, self.monitor.start_tolerance_rad,
                                     f"rad from every state measured within {self.start_window_s:g} s (motion {i}; "
                                     f"{len(near)} states there, the nearest {nearest:+.2f} s away)"))
        return out

    def assert_safe(self) -> None:
        found = self.monitor.violations + self.start_violations()
        assert found == [], "\n".join(map(str, found))


def goal_and_path(pre_touch_xyz, approach_dir, path_xyz, stamp_ns: int, frame_id: str = "world"):
    """PoseStamped whose x-axis is ``approach_dir`` and its Path (same stamp), in ``frame_id``."""
    x = np.asarray(approach_dir, float) / np.linalg.norm(approach_dir)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    R = np.column_stack([x, y, np.cross(x, y)])
    stamp = time_from_ns(stamp_ns)
    goal = pose_stamped(np.asarray(pre_touch_xyz, float), R, frame_id, stamp)
    path = PathMsg()
    path.header = goal.header
    for p in np.asarray(path_xyz, float).reshape(-1, 3):
        path.poses.append(pose_stamped(p, np.eye(3), frame_id, stamp))
    return goal, path


def done_values(msg) -> dict:
    return {kv.key: kv.value for kv in msg.values}


def diag_values(msg) -> dict:
    return {kv.key: kv.value for kv in msg.status[0].values}


def log_count(graph, name: str, pattern: str) -> int:
    """How many lines of node ``name``'s log match ``pattern``."""
    return len(re.findall(pattern, graph.procs[name].log()))


def pose_msg(xyz, frame_id: str = "world", stamp=None, q_xyzw=(0.0, 0.0, 0.0, 1.0)) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q_xyzw)
    return msg


def contact_rows(msg) -> np.ndarray:
    """(N, 4) x, y, z, label of a recorded CONTACT_DTYPE cloud (a rosbags message, decoded with numpy here)."""
    offsets = {f.name: f.offset for f in msg.fields}
    raw = np.frombuffer(bytes(msg.data), np.uint8).reshape(-1, msg.point_step)
    cols = [raw[:, offsets[k]:offsets[k] + 8].copy().view("<f8")[:, 0] for k in ("x", "y", "z")]
    return np.column_stack(cols + [raw[:, offsets["label"]].astype(float)])
