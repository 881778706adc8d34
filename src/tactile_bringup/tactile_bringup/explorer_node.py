"""Node ``explorer``: sequences touches over topics, measures progress, writes the report.

In:  /arm/fingertip_pose (waits for the tip at the start position),
     /planner/goal and /planner/path (the target and path of each decision), /planner/status (the answer
     to each request), /tactile/contacts (the touch's observation),
     /arm/touch_done (end of a touch).
Out: /planner/request (DiagnosticStatus: request id + map stamp to wait for).

The sequencing, ids, re-sends and time-outs are the ROS-free
:class:`~tactile_bringup.exploration_cycle.ExplorationCycle`; this node only
converts messages. It keeps a replica of the estimate (the estimator's own
core, fed the same observations with the same parameters) to compute IoU
and surface error against the simulated object, and writes ``report.json``
(the offline loop's schema), ``progress.png`` and the exports (shape files,
``contacts.ply``, ``estimate.json``) into ``out_dir``; with ``resume_from`` it
continues a run (:mod:`tactile_bringup.resume`). On the real rig (``evaluate: false``) it records the same
without ground truth. It sets ``done`` when the run ends, and on Ctrl-C
still writes the report so far.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from tactile_common import qos, topics
from tactile_common.cycle import PlanRequest
from tactile_common.cycle_msgs import answer_from_msg, report_from_msg, request_msg
from tactile_common.node_main import run_node
from tactile_common.observations_file import read_observations
from tactile_common.params import declare_parameters
from tactile_common.pointcloud import PointCloudError, from_pointcloud2
from tactile_common.stamps import stamp_ns
from tactile_driver.arm_msgs import path_axes, path_xyz

from .experiment import Experiment
from .exploration_cycle import CycleConfig, ExplorationCycle
from .progress import RunRecorder
from .resume import load_bundle


PARAMS = {
    "mode": ("2d", "'2d' or '3d'", {"choices": ("2d", "3d")}),
    "params_files": ([""], "the parameter files every node got (defaults, mode, user, overrides)"),
    "out_dir": ("runs/latest", "where report.json, progress.png and the shape go"),
    "evaluate": (True, "simulation: measure IoU and surface error against the object"),
    "start_tolerance_m": (0.003, "the tip counts as at the start position within this distance", {"gt": 0.0}),
    "start_timeout_s": (120.0, "give up if the tip does not reach the start position (wall clock)", {"gt": 0.0}),
    "answer_timeout_s": (15.0, "no answer to a plan request: send it again (wall clock)", {"gt": 0.0}),
    "touch_timeout_s": (60.0, "a touch that does not end: re-issue it under a new id (wall clock)", {"gt": 0.0}),
    "observation_timeout_s": (10.0, "a touch whose observation does not arrive: re-issue it (wall clock)", {"gt": 0.0}),
    "max_retries": (3, "re-sent requests / re-issued touches in a row before the run ends", {"ge": 0}),
    "abort_backoff_s": (2.0, "an aborted touch (stale joint states, e-stop) is re-issued after this, doubled for "
                        "each abort in a row; 0 = at once (wall clock)", {"ge": 0.0}),
    "max_unreachable": (10, "stop after this many unreachable goals in a row", {"ge": 1}),
    "resume_from": ("", "continue a run: its resume bundle (explore.sh --resume, tactile_bringup.resume); "
                    "'' = a new run"),
    **Experiment.RUN_PARAMETERS,  # touches, budgets, start position: read from the files, declared to show them
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
        self.run = RunRecorder(self.exp, Path(p.out_dir), evaluate=p.evaluate)
        if p.resume_from:
            report, observations_file = load_bundle(Path(p.resume_from))
            observations = read_observations(observations_file)
            self.run.restore(report, observations)
            self.get_logger().info(f"resumed after {len(self.run.touches)} touches ({len(observations)} "
                                   f"observations, travel {self.run.travel_m:.2f} m) from {p.resume_from}")
        cfg = CycleConfig(**{k: getattr(p, k) for k in CycleConfig.__dataclass_fields__})
        self.pub_request = self.create_publisher(DiagnosticStatus, topics.REQUEST, qos.EVENTS)
        self.cycle = ExplorationCycle(cfg, self.exp.start_tip_xyz, self.run, self.send_request, time.monotonic,
                                      lambda: self.get_clock().now().nanoseconds, self.get_logger())
        self.create_subscription(PoseStamped, topics.FINGERTIP_POSE, self.on_tip, qos.SENSOR)
        self.create_subscription(PoseStamped, topics.GOAL, self.on_goal, qos.EVENTS)
        self.create_subscription(PathMsg, topics.PATH, self.on_path, qos.EVENTS)
        self.create_subscription(DiagnosticStatus, topics.PLANNER_STATUS, self.on_planner_status, qos.EVENTS)
        self.create_subscription(PointCloud2, topics.CONTACTS, self.on_contacts, qos.OBSERVATIONS)
        self.create_subscription(DiagnosticStatus, topics.TOUCH_DONE, self.on_touch_done, qos.EVENTS)
        self.create_timer(0.2, self.on_timer)
        self._finish_logged = False
        self.get_logger().info(
            f"exploring '{self.exp.object_name}' ({self.exp.mode}) with '{self.exp.strategy}', "
            f"seed {self.exp.seed}, {self.exp.touches} touches; output in {p.out_dir}")

    @property
    def done(self) -> bool:  # run_node ends the spin when True
        return self.cycle.finished

    @property
    def exit_status(self) -> int:
        return self.cycle.exit_status

    def send_request(self, request: PlanRequest) -> None:
        self.pub_request.publish(request_msg(request))

    # -- inputs: messages to the cycle's events ------------------------------------------
    def on_tip(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        self.cycle.on_tip(np.array([p.x, p.y, p.z]))

    def on_goal(self, msg: PoseStamped) -> None:
        self.cycle.on_goal(stamp_ns(msg.header.stamp), msg)

    def on_path(self, msg: PathMsg) -> None:
        self.cycle.on_path(stamp_ns(msg.header.stamp), path_xyz(msg), path_axes(msg))

    def on_planner_status(self, msg: DiagnosticStatus) -> None:
        self._event(self.cycle.on_answer, answer_from_msg, msg, "planner status")

    def on_touch_done(self, msg: DiagnosticStatus) -> None:
        self._event(self.cycle.on_report, report_from_msg, msg, "touch_done")

    def on_contacts(self, msg: PointCloud2) -> None:
        try:
            points = from_pointcloud2(msg)
        except PointCloudError as exc:
            self.get_logger().warn(f"unreadable contact cloud: {exc}")
            return
        if len(points):
            self.cycle.on_observation(stamp_ns(msg.header.stamp), points[0])

    def _event(self, handle, parse, msg, what: str) -> None:
        try:
            event = parse(msg)
        except ValueError as exc:
            self.get_logger().warn(f"unreadable {what} ignored: {exc}")
            return
        handle(event)
        self._log_finish()

    def on_timer(self) -> None:
        self.cycle.tick()
        self._log_finish()

    def _log_finish(self) -> None:
        if self.cycle.finished and not self._finish_logged:
            self._finish_logged = True
            self.get_logger().info(f"finished ({self.cycle.reason}): {self.run.summary_line()}; "
                                   f"wrote {', '.join(self.cycle.written)}")

    def close(self) -> None:
        """Ctrl-C: keep what was measured."""
        self.cycle.interrupt()


def main(args=None) -> int:
    return run_node(ExplorerNode, args)
