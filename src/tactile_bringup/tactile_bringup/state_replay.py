"""Re-analysis of a saved estimate: ``scripts/replay.sh estimate.json --offline``.

No graph, no recording: rebuilds the estimate from the state file's observations
(:mod:`tactile_gpis.state`) with its estimator parameters, updated by the
``gpis_estimator`` section of the user's ``--params`` files (e.g. other
hyperparameters), measures it against the simulated object when the run's
parameter files are at hand (``<run folder>/params/`` next to the file, or the
files the state records), and writes report.json (no touches: the summary's
``final_iou`` is the loaded estimate's), progress.png and the exports to
``--out`` (default ``<folder of the file>/reanalysis_state``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Optional, Sequence

from tactile_common.params_file import node_params
from tactile_gpis.estimator import PARAMETERS
from tactile_gpis.state import build_estimator, read_state

from .cli_common import check_outputs, run_main
from .evaluation import Evaluator
from .experiment import Experiment
from .progress import write_outputs
from .report import make_report


def _experiment(state_path: Path, doc: dict, user_params: Sequence[Path]) -> Optional[Experiment]:
    """The run's experiment: its folder's params/ (graph run) or the files and overrides
    the state records (offline run); None when those files are gone."""
    mode = str(doc["params"].get("mode", "2d"))
    run = doc.get("run") or {}
    config = run.get("config") or {}
    folder_files = sorted((state_path.parent / "params").glob("*.yaml"))
    recorded = [Path(f) for f in config.get("params_files") or []]
    if folder_files:
        return Experiment.from_files(mode, [str(f) for f in folder_files + list(user_params)])
    if recorded and all(f.is_file() for f in recorded):
        exp = Experiment.from_files(mode, [str(f) for f in recorded + list(user_params)])
        overrides = config.get("overrides") or {}
        if isinstance(overrides, dict) and "sim_rig" in overrides:
            exp.overrides = overrides
            exp.object_name = None
            exp._resolve()
            exp.seed = int(exp.node_params("soc_planner").get("seed", 0))
        return exp
    return None


def reanalyse_state(path: Path, out_dir: Path, user_params: Sequence[Path] = (), evaluate: bool = True) -> dict:
    """Rebuild, measure and export a saved estimate; returns the report."""
    doc = read_state(path)
    override: dict[str, Any] = {k: v for k, v in node_params(list(user_params), "gpis_estimator").items()
                                if k in PARAMETERS} if user_params else {}
    if override.pop("mode", doc["params"].get("mode")) != doc["params"].get("mode"):
        raise ValueError(f"{path} holds a {doc['params'].get('mode')} estimate: --params cannot change its mode")
    changed = sorted(k for k, v in override.items() if doc["params"].get(k) != v)
    est, rejected = build_estimator(doc, path, {k: override[k] for k in changed} or None)
    exp = _experiment(path, doc, user_params) if evaluate else None
    evaluator = None
    if exp is not None:
        exp.overrides["gpis_estimator"] = dict(est.params)  # the estimate measured is this one
        evaluator = Evaluator(exp)
    run = doc.get("run") or {}
    report = make_report(run.get("object") or (exp.object_name if exp else "unknown"), est.params["mode"],
                         run.get("strategy") or (exp.strategy if exp else "unknown"), int(run.get("seed") or 0),
                         exp.config_summary() if exp else {"gpis_estimator": est.params}, [],
                         evaluator.iou(est) if evaluator else None, "re-analysed a saved estimate")
    report["loaded_state"] = {"path": str(path), "observations": est.n_observations,
                              "rejected_on_load": rejected, "params_changed": changed,
                              "evaluated": evaluator is not None}
    write_outputs(report, est, evaluator, out_dir, est.params["mode"])
    return report


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="replay.sh ESTIMATE.json --offline", description=__doc__.splitlines()[0])
    parser.add_argument("state", type=Path, help="estimate.json of a run folder")
    parser.add_argument("--params", type=Path, action="append", default=[],
                        help="parameter file whose gpis_estimator section overrides the state's (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default <folder>/reanalysis_state)")
    parser.add_argument("--no-evaluate", action="store_true", help="no ground truth (a real-rig run)")
    args = parser.parse_args(argv)

    def body() -> int:
        out = args.out or args.state.parent / "reanalysis_state"
        check_outputs((out, "--out", True))  # before the re-analysis, not after it
        report = reanalyse_state(args.state, out, args.params, evaluate=not args.no_evaluate)
        s, info = report["summary"], report["loaded_state"]
        iou = "n/a (no ground truth)" if s["final_iou"] is None else f"{s['final_iou']:.3f}"
        changed = ", ".join(info["params_changed"]) or "none"
        print(f"{info['observations']} observations rebuilt ({info['rejected_on_load']} rejected; parameters "
              f"changed: {changed}): IoU {iou}; wrote {out}")
        return 0

    return run_main(body)


if __name__ == "__main__":
    sys.exit(main())
