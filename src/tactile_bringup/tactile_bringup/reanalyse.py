"""Offline re-analysis of a recorded run: ``scripts/replay.sh run.mcap --offline``.

No graph: rebuilds the estimate from the recorded observations
(``/tactile/contacts``) in the order the touches ended (``/arm/touch_done``),
with the recorded targets (``/planner/goal``) and decision times
(``/planner/status``), re-makes every decision with the planner the graph
ran (``decisions`` in the report: graph and offline targets, and whether they
agree), recomputes the report and figures, and writes them
to ``--out`` (default: ``<run folder>/reanalysis``). Parameters: the files
the run's nodes got (``<run folder>/params/``), then the user's ``--params``
(e.g. other GPIS hyperparameters).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
from rclpy.serialization import deserialize_message

from tactile_common import topics
from tactile_common.cycle_msgs import request_from_msg
from tactile_common.params_file import node_params
from tactile_common.pointcloud import from_pointcloud2
from tactile_common.stamps import stamp_ns

from .bag_ros import message_class
from .cli_common import run_main
from .cores import make_planner
from .experiment import Experiment
from .player import Recording
from .progress import RunRecorder, write_outputs


def run_params_files(bag: Path) -> list[Path]:
    """The parameter files a run's nodes got, saved by explore.sh next to the recording."""
    params_dir = bag.parent / "params"
    files = sorted(params_dir.glob("*.yaml"))
    if not files:
        raise ValueError(f"{params_dir} holds no parameter files: re-analysis needs the run folder "
                         "written by scripts/explore.sh (or pass --params with every node's files)")
    return files


def reanalyse(bag: Path, out_dir: Path, user_params: Sequence[Path] = (), evaluate: bool = True) -> dict:
    """Rebuild the run's report from its recording; returns the report."""
    recording = Recording(bag)
    files = run_params_files(bag) + [Path(p) for p in user_params]
    mode = str(node_params(files, "gpis_estimator").get("mode", "2d"))
    exp = Experiment.from_files(mode, [str(f) for f in files])
    run = RunRecorder(exp, out_dir, evaluate=evaluate)
    # The planner the graph ran, re-run on the rebuilt estimate before each
    # touch: with the same code, parameters and seed it must choose the same
    # targets from the same observations (sensing noise aside).
    planner = make_planner(exp)
    tip = np.asarray(exp.start_tip_xyz, dtype=float)
    decisions: list[dict] = []
    wanted = [t for t in (topics.CONTACTS, topics.GOAL, topics.PLANNER_STATUS, topics.TOUCH_DONE, topics.REQUEST)
              if t in recording.topics]
    if topics.TOUCH_DONE not in wanted or topics.CONTACTS not in wanted:
        raise ValueError(f"{bag} has no {topics.TOUCH_DONE} or {topics.CONTACTS}: not an exploration run")
    types = {t: message_class(recording.topics[t].type_name) for t in wanted}
    observations, goals, decision_ms, starts, done_goals = {}, {}, {}, {}, set()
    for topic, _, data in recording.messages(wanted):
        msg = deserialize_message(data, types[topic])
        if topic == topics.REQUEST:  # where each touch was planned from (request id = goal stamp)
            req = request_from_msg(msg)
            starts[req.request_id] = req.start_xyz_m
            continue
        if topic == topics.CONTACTS:
            points = from_pointcloud2(msg)
            if len(points):
                observations[stamp_ns(msg.header.stamp)] = points[0]
        elif topic == topics.GOAL:
            goals[stamp_ns(msg.header.stamp)] = msg
        elif topic == topics.PLANNER_STATUS:
            values = {kv.key: kv.value for kv in msg.values}
            if "decision_ms" in values:
                decision_ms[int(values.get("stamp_ns", 0) or 0)] = float(values["decision_ms"])
        else:
            values = {kv.key: kv.value for kv in msg.values}
            travel, duration = float(values.get("travel_m") or 0), float(values.get("duration_s") or 0)
            obs_ns = int(values.get("observation_stamp_ns") or 0)
            goal_ns = int(values.get("goal_stamp_ns") or 0)
            if goal_ns in done_goals:
                continue  # a report sent again (durable topics): one touch
            done_goals.add(goal_ns)
            if msg.message in ("contact", "free_space") and obs_ns in observations:
                if starts.get(goal_ns) is not None:
                    tip = np.asarray(starts[goal_ns], dtype=float)
                plan = planner.plan(run.estimator.map_array(), tip)
                record = run.add_touch(goals.get(goal_ns), observations.pop(obs_ns), travel, duration,
                                       decision_ms.get(goal_ns, float("nan")))
                offline = plan.target_xyz if plan.ok else np.full(3, np.nan)
                decisions.append({"index": record["index"], "graph_target": record["target"],
                                  "offline_target": [float(v) for v in offline],
                                  "same": bool(np.linalg.norm(np.subtract(record["target"], offline)) < 1e-6)})
                if goals.get(goal_ns) is not None:
                    p = goals[goal_ns].pose.position
                    tip = np.array([p.x, p.y, p.z])
            else:
                run.add_travel(travel, duration)
    report = run.report("recording ended")
    report["summary"]["decisions_same_as_graph"] = sum(d["same"] for d in decisions)
    report["decisions"] = decisions
    write_outputs(report, run.estimator, run.evaluator, out_dir, exp.mode)
    return report


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="replay.sh RUN.mcap --offline", description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path, help="run.mcap of a run folder")
    parser.add_argument("--params", type=Path, action="append", default=[], help="parameter overrides (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default <run>/reanalysis)")
    parser.add_argument("--no-evaluate", action="store_true", help="no ground truth (a real-rig run)")
    args = parser.parse_args(argv)

    def body() -> int:
        out = args.out or args.bag.parent / "reanalysis"
        report = reanalyse(args.bag, out, args.params, evaluate=not args.no_evaluate)
        s = report["summary"]
        iou = "n/a" if s["final_iou"] is None else f"{s['final_iou']:.3f}"
        print(f"{s['touches']} touches re-analysed: final IoU {iou}, travel {s['travel_m']:.2f} m; "
              f"{s['decisions_same_as_graph']}/{s['touches']} decisions re-made identically; wrote {out}")
        return 0

    return run_main(body)


if __name__ == "__main__":
    sys.exit(main())
