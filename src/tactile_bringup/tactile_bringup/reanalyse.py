"""Offline re-analysis of a recorded run: ``scripts/replay.sh run.mcap --offline``.

No graph: rebuilds the estimate from the recorded observations
(``/tactile/contacts``) in the order the touches ended (``/arm/touch_done``),
with the recorded targets (``/planner/goal``) and decision times
(``/planner/status``), re-makes every decision with the planner the graph
ran (``decisions`` in the report: graph and offline targets, and whether they
agree), recomputes the report and figures, and writes them
to ``--out`` (default: ``<run folder>/reanalysis``). A resumed run
(``explore.sh --resume``) is re-analysed whole: ``run.mcap`` and then each
``run.resume<k>.mcap`` of its folder. Parameters: the files
the run's nodes got (``<run folder>/params/``), then the user's ``--params``
(e.g. other GPIS hyperparameters).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
from rclpy.serialization import deserialize_message

from tactile_common import topics
from tactile_common.cycle_msgs import request_from_msg
from tactile_common.fields import CONTACT_DTYPE
from tactile_common.params_file import node_params
from tactile_common.pointcloud import from_pointcloud2
from tactile_common.stamps import stamp_ns

from .bag_ros import message_class
from .cli_common import check_outputs, run_main
from .cores import make_planner
from .experiment import Experiment
from .player import Recording
from .slide_stream import graph_slide, is_stream, report_of
from .progress import RunRecorder, misses_before_contact, observe_record, write_outputs


def run_params_files(bag: Path) -> list[Path]:
    """The parameter files a run's nodes got, saved by explore.sh next to the recording."""
    params_dir = bag.parent / "params"
    files = sorted(params_dir.glob("*.yaml"))
    if not files:
        raise ValueError(f"{params_dir} holds no parameter files: re-analysis needs the run folder "
                         "written by scripts/explore.sh (or pass --params with every node's files)")
    return files


def run_sessions(bag: Path) -> list[list[Path]]:
    """The recordings of a run, graph session by graph session.

    A run folder's ``run.mcap`` is the first session; a recorder restarted by
    explore.sh went on in ``run.1.mcap``, ``run.2.mcap`` ... (same session); each
    ``explore.sh --resume`` is a session of its own, ``run.resume<k>.mcap`` (and its
    restarts ``run.resume<k>.<j>.mcap``). Another file name is one session of one file.
    """
    bag = Path(bag)
    if bag.name != "run.mcap":
        return [[bag]]

    def with_restarts(stem: str) -> list[Path]:
        restarts = sorted(bag.parent.glob(f"{stem}.[0-9]*.mcap"), key=lambda f: int(f.name.split(".")[-2]))
        return [bag.parent / f"{stem}.mcap", *restarts]

    sessions = [with_restarts("run")]
    k = 1
    while (bag.parent / f"run.resume{k}.mcap").is_file():
        sessions.append(with_restarts(f"run.resume{k}"))
        k += 1
    return sessions


@dataclass
class Rebuilt:
    """A run rebuilt from its recordings: the experiment, the run recorder (estimate and touch
    records), the re-made decisions, every observation in the order the estimate took it
    (CONTACT_DTYPE), and the number of graph sessions."""

    experiment: Experiment
    run: RunRecorder
    decisions: list
    observations: np.ndarray
    sessions: int


def rebuild(bag: Path, out_dir: Path, user_params: Sequence[Path] = (), evaluate: bool = True,
            remake_decisions: bool = True, resuming: bool = False) -> Rebuilt:
    """Replay a run's recorded observations into the estimate, touch by touch, session by session.

    Within a session events are deduplicated by their ids (a restarted recorder is handed the
    durable history again). An observation whose touch never ended (the touch in flight when a
    session was interrupted) is added when the next session starts, as the resumed estimator
    added it (:mod:`tactile_bringup.resume`); ``resuming``: the last session's too (a session
    is about to follow it).
    """
    files = run_params_files(bag) + [Path(p) for p in user_params]
    mode = str(node_params(files, "gpis_estimator").get("mode", "2d"))
    exp = Experiment.from_files(mode, [str(f) for f in files])
    run = RunRecorder(exp, out_dir, evaluate=evaluate)
    # The planner the graph ran, re-run on the rebuilt estimate before each
    # touch: with the same code, parameters and seed it must choose the same
    # targets from the same observations (sensing noise aside).
    planner = make_planner(exp) if remake_decisions else None
    decisions: list[dict] = []
    taken: list[np.ndarray] = []
    sessions = run_sessions(bag)
    for k, session in enumerate(sessions):
        orphans = _replay_session(session, exp, run, planner, decisions, taken)
        if k + 1 < len(sessions) or resuming:
            for stamp in sorted(orphans):
                observe_record(run.estimator, orphans[stamp])
                taken.append(orphans[stamp])
    observations = np.array(taken, dtype=CONTACT_DTYPE) if taken else np.zeros(0, dtype=CONTACT_DTYPE)
    return Rebuilt(exp, run, decisions, observations, len(sessions))


def _replay_session(files: Sequence[Path], exp: Experiment, run: RunRecorder, planner, decisions: list,
                    taken: list) -> dict:
    """One graph session's touches into ``run``; returns its observations no touch took (by stamp)."""
    tip = np.asarray(exp.start_tip_xyz, dtype=float)
    observations, goals, decision_ms, requests, done_goals, used = {}, {}, {}, {}, set(), set()
    for path in files:
        recording = Recording(path)
        wanted = [t for t in (topics.CONTACTS, topics.GOAL, topics.PLANNER_STATUS, topics.TOUCH_DONE,
                              topics.REQUEST) if t in recording.topics]
        if topics.TOUCH_DONE not in wanted or topics.CONTACTS not in wanted:
            if path == files[0]:
                raise ValueError(f"{path} has no {topics.TOUCH_DONE} or {topics.CONTACTS}: not an exploration run")
            continue  # a restarted recorder that stopped before anything happened
        types = {t: message_class(recording.topics[t].type_name) for t in wanted}
        for topic, _, data in recording.messages(wanted):
            msg = deserialize_message(data, types[topic])
            if topic == topics.REQUEST:  # where each touch was planned from, with the run's history
                req = request_from_msg(msg)  # (request id = goal stamp)
                requests[req.request_id] = req
                continue
            if topic == topics.CONTACTS:
                points = from_pointcloud2(msg)
                stamp = stamp_ns(msg.header.stamp)
                if len(points) and stamp not in used:
                    observations[stamp] = points[0]
            elif topic == topics.GOAL:  # the first goal of a stamp: the one the commander ran
                goals.setdefault(stamp_ns(msg.header.stamp), msg)
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
                slide = None
                if msg.message in ("contact", "free_space") and obs_ns in observations:
                    report = report_of(msg.message, values)
                    slide = graph_slide(report, observations) if is_stream(report) else None
                    if slide is not None:  # a slide: its whole stream (tactile_bringup.slide_stream)
                        for stamp, obs in zip(slide.stamps_ns[:-1], slide.observations[:-1]):
                            used.add(stamp)
                            taken.append(obs)
                            observations.pop(stamp)
                if msg.message in ("contact", "free_space") and obs_ns in observations:
                    req = requests.get(goal_ns)
                    if req is not None and req.start_xyz_m is not None:
                        tip = np.asarray(req.start_xyz_m, dtype=float)
                    excluded = visited = fruitless = last_var = None  # the graph's history, if the request had it
                    if req is not None:
                        excluded, visited, fruitless = (None if h is None else np.array(h, dtype=float).reshape(-1, 3)
                                                        for h in (req.excluded_xyz_m, req.visited_xyz_m,
                                                                  req.fruitless_xyz_m))
                        last_var = req.last_target_var_m2
                    misses = req.misses_before_contact if req is not None else misses_before_contact(run.touches)
                    plan = planner.plan(run.estimator.map_array(), tip, excluded, visited, misses, fruitless,
                                        last_var) if planner is not None else None
                    used.add(obs_ns)
                    taken.append(observations[obs_ns])
                    record = run.add_touch(goals.get(goal_ns), observations.pop(obs_ns), travel, duration,
                                           decision_ms.get(goal_ns, float("nan")), slide=slide)
                    if plan is not None:
                        offline = plan.target_xyz if plan.ok else np.full(3, np.nan)
                        decisions.append({"index": record["index"], "graph_target": record["target"],
                                          "offline_target": [float(v) for v in offline],
                                          "same": bool(np.linalg.norm(np.subtract(record["target"], offline))
                                                       < 1e-6)})
                    if goals.get(goal_ns) is not None:
                        p = goals[goal_ns].pose.position
                        tip = np.array([p.x, p.y, p.z])
                else:
                    run.add_travel(travel, duration)
    return observations


def reanalyse(bag: Path, out_dir: Path, user_params: Sequence[Path] = (), evaluate: bool = True) -> dict:
    """Rebuild the run's report from its recordings (every session, :func:`run_sessions`); returns it."""
    rebuilt = rebuild(bag, out_dir, user_params, evaluate)
    run, decisions = rebuilt.run, rebuilt.decisions
    report = run.report("recording ended")
    report["summary"]["decisions_same_as_graph"] = sum(d["same"] for d in decisions)
    report["summary"]["sessions"] = rebuilt.sessions
    report["decisions"] = decisions
    write_outputs(report, run.estimator, run.evaluator, out_dir, rebuilt.experiment.mode)
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
        check_outputs((out, "--out", True))  # before the re-analysis, not after it
        report = reanalyse(args.bag, out, args.params, evaluate=not args.no_evaluate)
        s = report["summary"]
        iou = "n/a" if s["final_iou"] is None else f"{s['final_iou']:.3f}"
        sessions = f" ({s['sessions']} sessions: the run was resumed)" if s["sessions"] > 1 else ""
        print(f"{s['touches']} touches re-analysed{sessions}: final IoU {iou}, travel {s['travel_m']:.2f} m; "
              f"{s['decisions_same_as_graph']}/{s['touches']} decisions re-made identically; wrote {out}")
        return 0

    return run_main(body)


if __name__ == "__main__":
    sys.exit(main())
