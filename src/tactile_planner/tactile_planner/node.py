"""soc_planner node: variance map + fingertip pose + request → goal pose, path, status.

Wiring: /gpis/variance_map (MAP), /arm/fingertip_pose (SENSOR), /planner/request
(diagnostic_msgs/DiagnosticStatus: request id, the map stamp to wait for, the
run's history: targets so far and those unreachable), /arm/touch_done →
TouchPlanner.plan → /planner/goal (PoseStamped, x-axis = −normal),
/planner/path (nav_msgs/Path), /planner/status (the answer to every request).
With ``touch: slide`` a slide goal also carries its direction (the goal's
y-axis) and its length (the path's last segment, the slide marker):
:mod:`tactile_common.slide_goal`.

Delivery (docs/architecture.md): goal and path are stamped with the request
id they answer; which requests are answered, and how, is
:class:`tactile_planner.request_inbox.RequestInbox`. The planner's memory
(targets so far, those unreachable) comes with each request, so a restarted
planner answers the current request as the dead one would have; without it
(an older client), what this node remembers.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from tactile_common import qos, topics
from tactile_common.cycle import PlannerAnswer, PlanRequest, TouchOutcome, xyz_text
from tactile_common.cycle_msgs import answer_msg, report_from_msg, request_from_msg
from tactile_common.finger_axis import EZ, finger_frame
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.slide_goal import encode_path, slide_rotation
from tactile_common.pointcloud import PointCloudError, from_pointcloud2
from tactile_common.stamps import stamp_ns, time_from_ns

from .maps import MapError, parse_variance_map
from .planner import NODE_PARAMETERS, PARAMETERS, PlanResult, TouchPlanner
from .pose import approach_rotation, quaternion_xyzw
from .request_inbox import RequestInbox, Verdict


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
        self.request: Optional[tuple[PlanRequest, int]] = None  # (pending request, received at clock ns)
        self.inbox = RequestInbox()  # answers: (goal, path, status) messages
        self.goal_targets: dict[int, np.ndarray] = {}
        self.excluded: dict[int, np.ndarray] = {}  # goal stamp -> target reported unreachable
        self.invalid_inputs = 0
        self.pub_goal = self.create_publisher(PoseStamped, topics.GOAL, qos.EVENTS)
        self.pub_path = self.create_publisher(Path, topics.PATH, qos.EVENTS)
        self.pub_status = self.create_publisher(DiagnosticStatus, topics.PLANNER_STATUS, qos.EVENTS)
        self.create_subscription(PointCloud2, topics.VARIANCE_MAP, self.on_map, qos.MAP)
        self.create_subscription(PoseStamped, topics.FINGERTIP_POSE, self.on_tip, qos.SENSOR)
        self.create_subscription(DiagnosticStatus, topics.REQUEST, self.on_request, qos.EVENTS)
        self.create_subscription(DiagnosticStatus, topics.TOUCH_DONE, self.on_touch_done, qos.EVENTS)
        self.create_timer(0.5, self.check_timeout)
        self.get_logger().info(
            f"soc_planner: mode {values['mode']}, strategy {values['strategy']}, backend {values['backend']}")

    # -- inputs -----------------------------------------------------------
    def on_map(self, msg: PointCloud2) -> None:
        try:  # a bad map never replaces the last good one
            if msg.header.frame_id != self.frame_id:
                raise MapError(f"frame_id '{msg.header.frame_id}', expected '{self.frame_id}'")
            arr = from_pointcloud2(msg)
            parse_variance_map(arr)
            self.map = arr
        except (PointCloudError, MapError) as exc:
            self.invalid_inputs += 1
            self.get_logger().error(f"invalid variance map ignored ({self.invalid_inputs} so far): {exc}")
            return
        self.map_stamp_ns = stamp_ns(msg.header.stamp)
        self.try_plan()

    def on_tip(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        tip = np.array([p.x, p.y, p.z])
        if not np.isfinite(tip).all() or msg.header.frame_id != self.frame_id:
            self.invalid_inputs += 1
            self.get_logger().warn(f"fingertip pose ignored: {np.round(tip, 4).tolist()} in frame "
                                   f"'{msg.header.frame_id}' (expected finite, in '{self.frame_id}')",
                                   throttle_duration_sec=5.0)
            return
        self.tip = tip
        self.try_plan()

    def on_request(self, msg: DiagnosticStatus) -> None:
        try:
            req = request_from_msg(msg)
        except ValueError as exc:
            self.invalid_inputs += 1
            self.get_logger().warn(f"invalid plan request ignored: {exc}")
            return
        verdict, answer = self.inbox.on_request(req.request_id)
        if verdict is Verdict.RESEND_ANSWER:
            for pub, msg_out in zip((self.pub_goal, self.pub_path, self.pub_status), answer):
                if msg_out is not None:
                    pub.publish(msg_out)
        if verdict is not Verdict.PLAN:
            return
        self.request = (req, self.get_clock().now().nanoseconds)
        self.try_plan()

    def on_touch_done(self, msg: DiagnosticStatus) -> None:
        try:
            report = report_from_msg(msg)
        except ValueError as exc:
            self.invalid_inputs += 1
            self.get_logger().warn(f"invalid touch_done ignored: {exc}")
            return
        self.inbox.touch_ended(report.goal_stamp_ns)
        if report.outcome is not TouchOutcome.UNREACHABLE or report.goal_stamp_ns in self.excluded:
            return
        target = self.goal_targets.get(report.goal_stamp_ns)
        if target is None:
            self.get_logger().warn(f"'unreachable' for an unknown goal stamp {report.goal_stamp_ns}")
            return
        self.excluded[report.goal_stamp_ns] = target
        self.get_logger().info(f"excluding candidates near {np.round(target, 3).tolist()} (reported unreachable)")

    # -- decision ---------------------------------------------------------
    def try_plan(self) -> None:
        if self.request is None or self.map is None:
            return
        req = self.request[0]
        # From the touch's nominal start when the request names it (the offline loop's rule), else measured.
        start = np.asarray(req.start_xyz_m, dtype=float) if req.start_xyz_m is not None else self.tip
        if start is None or self.map_stamp_ns < req.min_map_stamp_ns:
            return
        self.request = None
        # The request's history when it carries one (a restarted planner decides as before), else our memory.
        excluded = req.excluded_xyz_m if req.excluded_xyz_m is not None else list(self.excluded.values())
        visited = None if req.visited_xyz_m is None else np.array(req.visited_xyz_m, dtype=float).reshape(-1, 3)
        fruitless = None if req.fruitless_xyz_m is None else np.array(req.fruitless_xyz_m, dtype=float).reshape(-1, 3)
        res = self.planner.plan(self.map, start, np.array(excluded, dtype=float).reshape(-1, 3), visited,
                                req.misses_before_contact, fruitless, req.last_target_var_m2)
        stamp = time_from_ns(req.request_id)  # the goal's id: the request it answers
        goal = path = None
        if res.ok:
            self.goal_targets[req.request_id] = res.target_xyz.copy()
            goal, path = self.goal_msg(res, stamp), self.path_msg(res, stamp)
            self.pub_goal.publish(goal)
            self.pub_path.publish(path)
            self.get_logger().info(f"goal {req.request_id}: {res.message} ({res.decision_ms:.1f} ms)")
        else:
            self.get_logger().warn(f"no goal for request {req.request_id}: {res.status}: {res.message}")
        status = self.status_msg(req.request_id, res.status, res.message, res)
        self.pub_status.publish(status)
        self.inbox.answered(req.request_id, (goal, path, status))

    def check_timeout(self) -> None:
        if self.request is None:
            return
        req, received_ns = self.request
        waited_s = (self.get_clock().now().nanoseconds - received_ns) * 1e-9
        if waited_s > self.timeout_s:
            missing = "a map at least as new as the request" if self.map_stamp_ns < req.min_map_stamp_ns \
                else "a fingertip pose"
            if self.map is None:
                missing = "a variance map"
            self.request = None  # not stored: the explorer's re-sent request is tried again
            msg = f"no goal after {waited_s:.0f} s: still waiting for {missing}"
            self.get_logger().warn(msg)
            self.pub_status.publish(self.status_msg(req.request_id, "timeout", msg, None))

    # -- messages ---------------------------------------------------------
    def header(self, stamp) -> Header:
        return Header(frame_id=self.frame_id, stamp=stamp)

    @staticmethod
    def _is_slide(res: PlanResult) -> bool:
        return bool(np.isfinite(res.slide_length_m) and np.all(np.isfinite(res.slide_direction_xyz)))

    def _rotation(self, res: PlanResult) -> np.ndarray:
        """x = the approach (−n); a slide: y = its direction (tactile_common.slide_goal)."""
        if self._is_slide(res):
            return slide_rotation(-np.asarray(res.normal_xyz, dtype=float), res.slide_direction_xyz)
        return approach_rotation(res.normal_xyz)

    def goal_msg(self, res: PlanResult, stamp) -> PoseStamped:
        msg = PoseStamped(header=self.header(stamp))
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, res.pretouch_xyz)
        q = quaternion_xyzw(self._rotation(res))
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = map(float, q)
        return msg

    def path_msg(self, res: PlanResult, stamp) -> Path:
        """The path; each pose's orientation is the finger's frame there (tactile_common.finger_axis)."""
        path = Path(header=self.header(stamp))
        points = res.path_xyz
        axes = res.path_axes_xyz if len(res.path_axes_xyz) else np.tile(EZ, (len(points), 1))
        if self._is_slide(res):  # the slide marker after the pre-touch point
            points = encode_path(points, res.pretouch_xyz, res.slide_direction_xyz, res.slide_length_m)
            axes = np.vstack([axes, np.tile(EZ, (len(points) - len(axes), 1))])
        approach = -np.asarray(res.normal_xyz, dtype=float)
        for pt, axis in zip(points, axes):
            q = quaternion_xyzw(finger_frame(approach, axis))
            ps = PoseStamped(header=self.header(stamp))
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = map(float, pt)
            ps.pose.orientation.x, ps.pose.orientation.y, ps.pose.orientation.z, ps.pose.orientation.w = map(float, q)
            path.poses.append(ps)
        return path

    def status_msg(self, request_id: int, status: str, message: str,
                   res: Optional[PlanResult]) -> DiagnosticStatus:
        extra = {"invalid_inputs": str(self.invalid_inputs)}
        if res is not None:
            extra.update({k: str(v) for k, v in (
                ("index", res.index), ("start_snapped", res.start_snapped), ("n_candidates", res.n_candidates),
                ("n_unreachable", res.n_unreachable), ("n_excluded", res.n_excluded))})
            if res.ok:
                extra["target_xyz_m"] = xyz_text(res.target_xyz)
                if np.isfinite(res.target_var_m2):
                    extra["target_var_m2"] = repr(float(res.target_var_m2))
            extra["fruitless_xyz_m"] = ";".join(xyz_text(p) for p in res.fruitless_xyz)
        goal_ns = request_id if res is not None and res.ok else 0
        return answer_msg(PlannerAnswer(request_id, status, message, goal_ns,
                                        res.decision_ms if res is not None else float("nan"), extra))


def main(args=None) -> int:
    return run_node(SocPlannerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
