"""soc_planner node: variance map + fingertip pose + request → goal pose, path, status.

Wiring: /gpis/variance_map (MAP), /arm/fingertip_pose (SENSOR), /planner/request
(std_msgs/Header: plan on a map with stamp ≥ request stamp, waiting for it if
needed), /arm/touch_done ('unreachable' → exclude that goal's target) →
TouchPlanner.plan → /planner/goal (PoseStamped, x-axis = −normal),
/planner/path (nav_msgs/Path, same stamp), /planner/status (every decision).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from tactile_common import qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import PointCloudError, from_pointcloud2
from tactile_common.stamps import stamp_ns

from .planner import NODE_PARAMETERS, PARAMETERS, PlanResult, TouchPlanner
from .pose import approach_rotation, quaternion_xyzw

REQUEST = "/planner/request"
STATUS = "/planner/status"


class SocPlannerNode(Node):
    def __init__(self) -> None:
        super().__init__("soc_planner")
        p = declare_parameters(self, {**PARAMETERS, **NODE_PARAMETERS})
        values = vars(p)
        self.frame_id = values["frame_id"]
        self.timeout_s = float(values["request_timeout_s"])
        self.planner = TouchPlanner.from_params(
            {k: values[k] for k in PARAMETERS}, seed=int(values["seed"]))
        self.map: Optional[np.ndarray] = None
        self.map_stamp_ns = -1
        self.tip: Optional[np.ndarray] = None
        self.request: Optional[tuple[int, int]] = None  # (request stamp ns, received at clock ns)
        self.goal_targets: dict[int, np.ndarray] = {}
        self.excluded: list[np.ndarray] = []
        self.invalid_inputs = 0
        self.pub_goal = self.create_publisher(PoseStamped, topics.GOAL, qos.EVENTS)
        self.pub_path = self.create_publisher(Path, topics.PATH, qos.EVENTS)
        self.pub_status = self.create_publisher(DiagnosticStatus, STATUS, qos.EVENTS)
        self.create_subscription(PointCloud2, topics.VARIANCE_MAP, self.on_map, qos.MAP)
        self.create_subscription(PoseStamped, topics.FINGERTIP_POSE, self.on_tip, qos.SENSOR)
        self.create_subscription(Header, REQUEST, self.on_request, qos.EVENTS)
        self.create_subscription(DiagnosticStatus, topics.TOUCH_DONE, self.on_touch_done, qos.EVENTS)
        self.create_timer(0.5, self.check_timeout)
        self.get_logger().info(
            f"soc_planner: mode {values['mode']}, strategy {values['strategy']}, backend {values['backend']}")

    # -- inputs -----------------------------------------------------------
    def on_map(self, msg: PointCloud2) -> None:
        try:
            self.map = from_pointcloud2(msg)
        except PointCloudError as exc:
            self.invalid_inputs += 1
            self.get_logger().error(f"invalid variance map ignored ({self.invalid_inputs} so far): {exc}")
            return
        self.map_stamp_ns = stamp_ns(msg.header.stamp)
        self.try_plan()

    def on_tip(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        tip = np.array([p.x, p.y, p.z])
        if not np.isfinite(tip).all():
            self.invalid_inputs += 1
            self.get_logger().warn("non-finite fingertip pose ignored")
            return
        self.tip = tip
        self.try_plan()

    def on_request(self, msg: Header) -> None:
        self.request = (stamp_ns(msg.stamp), self.get_clock().now().nanoseconds)
        self.try_plan()

    def on_touch_done(self, msg: DiagnosticStatus) -> None:
        if msg.message != "unreachable":
            return
        values = {kv.key: kv.value for kv in msg.values}
        try:
            target = self.goal_targets[int(values.get("goal_stamp_ns", ""))]
        except (ValueError, KeyError):
            self.get_logger().warn(f"'unreachable' for an unknown goal stamp {values.get('goal_stamp_ns')!r}")
            return
        self.excluded.append(target)
        self.get_logger().info(f"excluding candidates near {np.round(target, 3).tolist()} (reported unreachable)")

    # -- decision ---------------------------------------------------------
    def try_plan(self) -> None:
        if self.request is None or self.map is None or self.tip is None:
            return
        if self.map_stamp_ns < self.request[0]:
            return
        self.request = None
        ex = np.array(self.excluded).reshape(-1, 3)
        res = self.planner.plan(self.map, self.tip, ex)
        stamp = self.get_clock().now().to_msg()
        if res.ok:
            self.goal_targets[stamp_ns(stamp)] = res.target_xyz.copy()
            self.pub_goal.publish(self.goal_msg(res, stamp))
            self.pub_path.publish(self.path_msg(res, stamp))
            self.get_logger().info(f"goal: {res.message} ({res.decision_ms:.1f} ms)")
        else:
            self.get_logger().warn(f"no goal: {res.status}: {res.message}")
        self.pub_status.publish(self.status_msg(res.status, res.message, stamp, res))

    def check_timeout(self) -> None:
        if self.request is None:
            return
        waited_s = (self.get_clock().now().nanoseconds - self.request[1]) * 1e-9
        if waited_s > self.timeout_s:
            missing = "a map at least as new as the request" if self.map_stamp_ns < self.request[0] else "a fingertip pose"
            if self.map is None:
                missing = "a variance map"
            self.request = None
            msg = f"no goal after {waited_s:.0f} s: still waiting for {missing}"
            self.get_logger().warn(msg)
            self.pub_status.publish(self.status_msg("timeout", msg, self.get_clock().now().to_msg(), None))

    # -- messages ---------------------------------------------------------
    def header(self, stamp) -> Header:
        return Header(frame_id=self.frame_id, stamp=stamp)

    def goal_msg(self, res: PlanResult, stamp) -> PoseStamped:
        msg = PoseStamped(header=self.header(stamp))
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, res.pretouch_xyz)
        q = quaternion_xyzw(approach_rotation(res.normal_xyz))
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = map(float, q)
        return msg

    def path_msg(self, res: PlanResult, stamp) -> Path:
        path = Path(header=self.header(stamp))
        q = quaternion_xyzw(approach_rotation(res.normal_xyz))
        for pt in res.path_xyz:
            ps = PoseStamped(header=self.header(stamp))
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = map(float, pt)
            ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z, ps.pose.orientation.w = map(float, q)
            path.poses.append(ps)
        return path

    def status_msg(self, status: str, message: str, stamp, res: Optional[PlanResult]) -> DiagnosticStatus:
        values = [KeyValue(key="detail", value=message), KeyValue(key="stamp_ns", value=str(stamp_ns(stamp))),
                  KeyValue(key="invalid_inputs", value=str(self.invalid_inputs))]
        if res is not None:
            values += [KeyValue(key=k, value=str(v)) for k, v in (
                ("index", res.index), ("decision_ms", f"{res.decision_ms:.2f}"),
                ("start_snapped", res.start_snapped), ("n_candidates", res.n_candidates),
                ("n_unreachable", res.n_unreachable), ("n_excluded", res.n_excluded))]
        level = DiagnosticStatus.OK if status == "ok" else DiagnosticStatus.WARN
        return DiagnosticStatus(level=level, name="soc_planner", message=status,
                                hardware_id="soc_planner", values=values)


def main(args=None) -> int:
    return run_node(SocPlannerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
