"""Node ``explorer``: sequences touches over topics, measures progress, writes the report.

In:  /arm/fingertip_pose (waits for the tip at the start position),
     /planner/goal (the target of each decision), /planner/status (decision
     time, or why no goal), /tactile/contacts (the touch's observation),
     /arm/touch_done (end of a touch).
Out: /planner/request (std_msgs/Header: plan on a map at least this new).

It keeps a replica of the estimate (the estimator's own core, fed the same
observations with the same parameters) to compute IoU and surface error
against the simulated object, and writes ``report.json`` (the offline
loop's schema), ``progress.png`` and the estimated shape into ``out_dir``.
On the real rig (``evaluate: false``) it records the same without ground
truth. It sets ``done`` when the run ends, and on Ctrl-C still writes the
report so far.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from tactile_common import fields, qos, topics
from tactile_common.node_main import run_node
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import PointCloudError, from_pointcloud2
from tactile_common.stamps import stamp_ns, time_from_ns

from .experiment import Experiment
from .progress import RunRecorder

REQUEST = "/planner/request"
PLANNER_STATUS = "/planner/status"

PARAMS = {
    "mode": ("2d", "'2d' or '3d'", {"choices": ("2d", "3d")}),
    "params_files": ([""], "the parameter files every node got (defaults, mode, user, overrides)"),
    "out_dir": ("runs/latest", "where report.json, progress.png and the shape go"),
    "evaluate": (True, "simulation: measure IoU and surface error against the object"),
    "start_tolerance_m": (0.003, "the tip counts as at the start position within this distance", {"gt": 0.0}),
    "start_timeout_s": (120.0, "give up if the tip does not reach the start position (wall clock)", {"gt": 0.0}),
    "touch_timeout_s": (120.0, "give up if a touch does not end (wall clock)", {"gt": 0.0}),
    "max_unreachable": (10, "stop after this many unreachable goals in a row", {"ge": 1}),
}


class ExplorerNode(Node):
    def __init__(self) -> None:
        super().__init__("explorer")
        p = declare_parameters(self, PARAMS)
        files = [f for f in p.params_files if f]
        if not files:
            raise ValueError("explorer: parameter 'params_files' is empty (start it through scripts/explore.sh)")
        # The files already hold the overrides (object, strategy, seed, touches).
        self.exp = Experiment.from_files(p.mode, files)
        self.p = p
        self.run = RunRecorder(self.exp, Path(p.out_dir), evaluate=p.evaluate)
        self.done = False
        self.exit_status = 0
        self.state = "waiting_for_start"
        self.last_tip_xyz: Optional[np.ndarray] = None
        self.last_answer_t: Optional[float] = None  # monotonic time of the planner's last status
        self.t_state = time.monotonic()
        self.last_obs_stamp_ns = 0
        self.unreachable_in_row = 0
        self.goals: dict[int, PoseStamped] = {}
        self.observations: dict[int, np.ndarray] = {}
        self.decision_ms: dict[int, float] = {}
        self.pending_done: Optional[DiagnosticStatus] = None
        self.pub_request = self.create_publisher(Header, REQUEST, qos.EVENTS)
        self.create_subscription(PoseStamped, topics.FINGERTIP_POSE, self.on_tip, qos.SENSOR)
        self.create_subscription(PoseStamped, topics.GOAL, self.on_goal, qos.EVENTS)
        self.create_subscription(DiagnosticStatus, PLANNER_STATUS, self.on_planner_status, qos.EVENTS)
        self.create_subscription(PointCloud2, topics.CONTACTS, self.on_contacts, qos.EVENTS)
        self.create_subscription(DiagnosticStatus, topics.TOUCH_DONE, self.on_touch_done, qos.EVENTS)
        self.create_timer(0.2, self.on_timer)
        self.get_logger().info(
            f"exploring '{self.exp.object_name}' ({self.exp.mode}) with '{self.exp.strategy}', "
            f"seed {self.exp.seed}, {self.exp.touches} touches; output in {p.out_dir}")

    # -- inputs ----------------------------------------------------------------
    def on_tip(self, msg: PoseStamped) -> None:
        if self.state != "waiting_for_start":
            return
        tip = np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
        self.last_tip_xyz = tip
        if np.linalg.norm(tip - self.exp.start_tip_xyz) <= self.p.start_tolerance_m and self.graph_ready():
            self.get_logger().info("tip at the start position: first decision")
            self.request(0)

    def graph_ready(self) -> bool:
        """The planner listens to our requests and the commander reports touches.

        A request is sent once (it is not idempotent: each one makes a goal), so
        it must not go out before discovery has matched the planner; under load
        that takes seconds. Seeing the planner's subscription in the graph is not
        enough: our writer must have matched it too (else the reliable sample is
        not kept for it and the request is lost), hence the publisher's own count.
        The recorder subscribes to everything: not counted as a planner.
        """
        subs = self.get_subscriptions_info_by_topic(REQUEST)
        planners = [i for i in subs if i.node_name != "recorder"]
        return (bool(planners) and self.pub_request.get_subscription_count() >= len(subs)
                and self.count_publishers(topics.TOUCH_DONE) > 0)

    def on_goal(self, msg: PoseStamped) -> None:
        self.goals[stamp_ns(msg.header.stamp)] = msg

    def on_planner_status(self, msg: DiagnosticStatus) -> None:
        self.last_answer_t = time.monotonic()
        values = {kv.key: kv.value for kv in msg.values}
        goal_stamp_ns = int(values.get("stamp_ns", "0") or 0)
        if "decision_ms" in values:
            self.decision_ms[goal_stamp_ns] = float(values["decision_ms"])
        if msg.message != "ok" and self.state == "touching":
            self.finish(f"planner: {msg.message}: {values.get('detail', '')}")

    def on_contacts(self, msg: PointCloud2) -> None:
        try:
            points = from_pointcloud2(msg)
        except PointCloudError as exc:
            self.get_logger().warn(f"unreadable contact cloud: {exc}")
            return
        if len(points):
            self.observations[stamp_ns(msg.header.stamp)] = points[0]

    def on_touch_done(self, msg: DiagnosticStatus) -> None:
        if self.state != "touching":
            return
        self.pending_done = msg
        self.try_complete_touch()

    # -- the cycle ---------------------------------------------------------------
    def request(self, min_stamp_ns: int) -> None:
        self.state = "touching"
        self.t_state = time.monotonic()
        self.pub_request.publish(Header(frame_id=topics.WORLD_FRAME, stamp=time_from_ns(min_stamp_ns)))

    def try_complete_touch(self) -> None:
        msg = self.pending_done
        values = {kv.key: kv.value for kv in msg.values}
        outcome = msg.message
        if outcome == "unreachable":
            self.pending_done = None
            self.unreachable_in_row += 1
            self.get_logger().warn(f"goal unreachable ({self.unreachable_in_row} in a row): re-planning")
            if self.unreachable_in_row >= self.p.max_unreachable:
                self.finish(f"{self.unreachable_in_row} unreachable goals in a row")
            else:
                self.run.add_travel(float(values.get("travel_m", 0) or 0), float(values.get("duration_s", 0) or 0))
                self.request(self.last_obs_stamp_ns)
            return
        if outcome not in ("contact", "free_space"):
            self.finish(f"touch {outcome}: {values}")
            self.exit_status = 1
            return
        obs_ns = int(values.get("observation_stamp_ns") or 0)
        if obs_ns not in self.observations:
            return  # the observation is still on its way: on_timer retries
        self.pending_done = None
        self.unreachable_in_row = 0
        goal_ns = int(values.get("goal_stamp_ns") or 0)
        record = self.run.add_touch(
            goal=self.goals.get(goal_ns), observation=self.observations.pop(obs_ns),
            travel_m=float(values.get("travel_m", 0) or 0), time_s=float(values.get("duration_s", 0) or 0),
            decision_ms=self.decision_ms.get(goal_ns, float("nan")),
        )
        self.get_logger().info(self.run.progress_line(record))
        self.last_obs_stamp_ns = obs_ns
        reason = self.run.stop_reason()
        if reason:
            self.finish(reason)
        else:
            self.request(obs_ns)

    def on_timer(self) -> None:
        if self.done:
            return
        if self.pending_done is not None:
            self.try_complete_touch()
        waited = time.monotonic() - self.t_state
        if self.state == "waiting_for_start" and waited > self.p.start_timeout_s:
            self.finish(self.start_failure())
            self.exit_status = 1
        elif self.state == "touching" and waited > self.p.touch_timeout_s:
            answered = self.last_answer_t is not None and self.last_answer_t >= self.t_state
            self.finish(f"no touch ended within {self.p.touch_timeout_s:.0f} s"
                        + ("" if answered else " (the planner never answered the request)"))
            self.exit_status = 1

    def start_failure(self) -> str:
        """Why the first decision never went out, in the words a rig user acts on."""
        if self.last_tip_xyz is None:
            return (f"no fingertip pose on {topics.FINGERTIP_POSE} within {self.p.start_timeout_s:.0f} s "
                    "(is the arm commander running?)")
        if np.linalg.norm(self.last_tip_xyz - self.exp.start_tip_xyz) > self.p.start_tolerance_m:
            start = np.round(self.exp.start_tip_xyz, 3).tolist()
            return (f"the fingertip never reached the start position {start} within {self.p.start_timeout_s:.0f} s: "
                    f"it is at {np.round(self.last_tip_xyz, 3).tolist()} (see the arm commander's log)")
        missing = "the planner" if self.count_publishers(topics.TOUCH_DONE) else "the arm commander's touch_done"
        return f"the tip is at the start but {missing} was not discovered within {self.p.start_timeout_s:.0f} s"

    def finish(self, reason: str) -> None:
        if self.done:
            return
        self.state = "finished"
        paths = self.run.write(reason)
        self.get_logger().info(f"finished ({reason}): {self.run.summary_line()}; wrote {', '.join(paths)}")
        self.done = True

    def close(self) -> None:
        """Ctrl-C: keep what was measured."""
        if not self.done:
            self.run.write("interrupted")


def main(args=None) -> int:
    return run_node(ExplorerNode, args)
