"""Continue an interrupted run: ``scripts/explore.sh --resume runs/<ts>`` (ROS-free preparation).

A run folder holds its parameters (``params/``) and its recordings, one graph
session each (:func:`tactile_bringup.reanalyse.run_sessions`). Resuming it:

1. recordings cut by a crash are recovered in place (every message up to the cut);
2. the run so far is rebuilt from the recorded observations, with the run's own
   parameters (:func:`tactile_bringup.reanalyse.rebuild`): its touch records and
   every observation the estimate took, including the one of a touch that was in
   flight when the run stopped;
3. the next session ``k`` gets a bundle ``resume<k>/``: ``observations.csv``
   (:mod:`tactile_common.observations_file`; the estimator and the explorer's
   replica start from it) and ``report_before.json`` (the touch records and the
   travel and robot time so far: the explorer continues them, so the final
   ``report.json`` covers the whole run);
4. ``params/resume<k>_overrides.yaml`` holds a new touch budget if one is given.

The new session records into ``run.resume<k>.mcap`` of the same folder. It
starts from the start position (the arm does not remember where it was), so its
first travel is measured from there.
"""

from __future__ import annotations

import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import yaml

from tactile_common.observations_file import write_observations
from tactile_common.params_file import node_params

from .mcap_recorder import recover
from .player import Recording
from .reanalyse import rebuild, run_sessions

BUNDLE_REPORT = "report_before.json"
BUNDLE_OBSERVATIONS = "observations.csv"


@dataclass(frozen=True)
class ResumePlan:
    """What explore.sh needs to start session ``session`` of a run."""

    session: int
    recording_stem: str  # the session's recording: <run>/<stem>.mcap
    bundle_dir: Path
    mode: str
    rig: str  # 'sim' (the run was evaluated against a simulated object) or 'hardware'
    params_files: list  # every node's files, in order (the run's own, then the resume overrides)
    touches_before: int
    touches: int


def _resume_index(path: Path) -> int:
    m = re.fullmatch(r"resume(\d+)_overrides\.yaml", path.name)
    return int(m.group(1)) if m else 0


def run_files(params_dir: Path) -> list[Path]:
    """The parameter files the run's nodes got (explore.sh's plan: ``NN_*.yaml``), then the resume
    overrides of earlier sessions in session order; not the launch files (``99_*``)."""
    plan = sorted(f for f in params_dir.glob("[0-8][0-9]_*.yaml"))
    resumes = sorted(params_dir.glob("resume*_overrides.yaml"), key=_resume_index)
    return plan + [f for f in resumes if _resume_index(f) > 0]


def _recover_cut(path: Path, log) -> None:
    """A recording cut by a crash is rewritten whole (every message up to the cut); the cut file is
    kept beside it as ``<name>.cut``. A file nothing can be read from is left as it is (ValueError)."""
    try:
        Recording(path)
    except ValueError as exc:
        if "not finalised" not in str(exc) and "not a readable" not in str(exc):
            raise
        tmp = path.with_name(path.name + ".recovering")
        try:
            n = recover(path, tmp)
        except Exception as err:  # noqa: BLE001 - whatever the reader makes of a damaged file
            tmp.unlink(missing_ok=True)
            raise ValueError(f"{path}: cannot be read or recovered ({err})") from None
        if n == 0:
            tmp.unlink(missing_ok=True)
            raise ValueError(f"{path}: not a recording (nothing in it can be recovered); it is left as it is")
        path.replace(path.with_name(path.name + ".cut"))
        tmp.replace(path)
        log(f"{path.name} was cut (the run was killed): recovered {n} messages; the cut file is {path.name}.cut")


def prepare(run_dir: Path, touches: Optional[int] = None, log=lambda line: print(line, file=sys.stderr)
            ) -> ResumePlan:
    """Check ``run_dir``, rebuild the run so far and write the next session's bundle (see the module doc).

    Raises ``ValueError`` (one line) for a folder that is not a run, or a run that has nothing left to do.
    """
    run_dir = Path(run_dir)
    bag = run_dir / "run.mcap"
    params_dir = run_dir / "params"
    if not run_dir.is_dir():
        raise ValueError(f"--resume {run_dir}: no such run folder")
    if not bag.is_file() or not params_dir.is_dir():
        raise ValueError(f"--resume {run_dir}: not a run folder of scripts/explore.sh (it needs run.mcap and "
                         "params/)")
    files = run_files(params_dir)
    if not files:
        raise ValueError(f"--resume {run_dir}: params/ holds none of the run's parameter files")
    if touches is not None and (isinstance(touches, bool) or int(touches) < 1):
        raise ValueError(f"--touches {touches}: must be a whole number >= 1")
    sessions = run_sessions(bag)
    for session in sessions:
        for path in session:
            _recover_cut(path, log)
    launch = node_params(sorted(params_dir.glob("99_launch*.yaml")), "explorer")
    mode = str(node_params(files, "gpis_estimator").get("mode", launch.get("mode", "2d")))
    evaluate = bool(launch.get("evaluate", True))
    k = len(sessions)
    bundle = run_dir / f"resume{k}"
    rebuilt = rebuild(bag, bundle, evaluate=evaluate, remake_decisions=False, resuming=True)
    done = len(rebuilt.run.touches)
    budget = int(touches) if touches is not None else int(rebuilt.experiment.touches)
    if done >= budget:
        raise ValueError(f"--resume {run_dir}: the run already made {done} touches of its budget {budget}: give "
                         f"--touches N (N > {done}) to continue it")
    bundle.mkdir(parents=True, exist_ok=True)
    write_observations(bundle / BUNDLE_OBSERVATIONS, rebuilt.observations)
    report = rebuilt.run.report("resumed")
    report["resume"] = {"session": k, "travel_m": rebuilt.run.travel_m, "time_s": rebuilt.run.time_s,
                        "observations": int(len(rebuilt.observations))}
    (bundle / BUNDLE_REPORT).write_text(json.dumps(report, indent=1))
    if touches is not None:
        override = params_dir / f"resume{k}_overrides.yaml"
        override.write_text(yaml.safe_dump({"explorer": {"ros__parameters": {"touches": budget}}}))
        files.append(override)
    log(f"resuming {run_dir.name} (session {k + 1}): {done} touches and {len(rebuilt.observations)} "
        f"observations so far, budget {budget}")
    return ResumePlan(k, f"run.resume{k}", bundle, mode, "sim" if evaluate else "hardware",
                      [str(f.resolve()) for f in files], done, budget)


def load_bundle(bundle_dir: Path) -> tuple[dict, Path]:
    """The report so far and the observations file of a resume bundle (``ValueError`` if unreadable)."""
    bundle_dir = Path(bundle_dir)
    try:
        report = json.loads((bundle_dir / BUNDLE_REPORT).read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"resume bundle {bundle_dir}: cannot read {BUNDLE_REPORT} ({exc})") from None
    if not isinstance(report, dict) or "touches" not in report or "resume" not in report:
        raise ValueError(f"resume bundle {bundle_dir}: {BUNDLE_REPORT} is not a resume report")
    return report, bundle_dir / BUNDLE_OBSERVATIONS
