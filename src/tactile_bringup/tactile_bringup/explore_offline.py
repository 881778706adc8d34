"""``tactile-explore-offline``: one exploration in simulation without ROS.

Example::

    tactile-explore-offline --object star --mode 2d --strategy proposed --touches 30 \\
        --seed 1 --report out.json --plot out.png
    tactile-explore-offline --object star --touches 30 --out runs/star      # a run folder
    tactile-explore-offline --object star --load-state runs/star/estimate.json --touches 10 --out runs/star+10
    tactile-explore-offline --object star --load-state runs/star/estimate.json --evaluate-only

``--out DIR`` writes what a graph run leaves (report.json, progress.png, the shape
files, contacts.ply, estimate.json: docs/recording.md, "Exports"). ``--load-state``
starts from a saved estimate (its estimator parameters and observations; ``--mode``
and ``--object`` default to the state's) and goes on for ``--touches`` more touches from the start
position, or with ``--evaluate-only`` just measures it (no touches).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional, Sequence

from tactile_gpis.state import build_estimator, read_state

from . import plots
from .cli_common import Parser, add_experiment_args, check_outputs, progress_line, run_main
from .experiment import Experiment
from .loop import ExplorationLoop
from .progress import write_outputs
from .report import check_report, make_report, write_report


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = Parser(prog="tactile-explore-offline", description=__doc__.splitlines()[0])
    add_experiment_args(parser)
    parser.add_argument("--report", type=Path, default=None,
                        help="report JSON path (default: report.json, or only DIR/report.json with --out)")
    parser.add_argument("--plot", type=Path, default=None, help="progress figure (PNG)")
    parser.add_argument("--shape", type=Path, default=None, help="export the estimate (2D .csv/.ply/.obj, 3D .ply/.stl/.obj)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="run folder: report.json, progress.png, shape files, contacts.ply, estimate.json")
    parser.add_argument("--load-state", type=Path, default=None, metavar="FILE",
                        help="start from a saved estimate (estimate.json of a run)")
    parser.add_argument("--evaluate-only", action="store_true",
                        help="with --load-state: measure the loaded estimate, no touches")
    parser.add_argument("--quiet", action="store_true", help="no per-touch progress")
    parser.set_defaults(mode=None)  # with --load-state the state's mode; else 2d
    args = parser.parse_args(argv)
    if args.evaluate_only and args.load_state is None:
        parser.error("--evaluate-only needs --load-state FILE")
    report_path = args.report or (args.out / "report.json" if args.out else Path("report.json"))

    def body() -> int:
        check_outputs((args.out, "--out", True),  # before the run, not after it
                      (report_path if (not args.out or args.report) else None, "--report", False),
                      (args.plot, "--plot", False), (args.shape, "--shape", False))
        state = read_state(args.load_state) if args.load_state else None
        mode = args.mode or (str(state["params"].get("mode", "2d")) if state else "2d")
        if state and str(state["params"].get("mode")) != mode:
            raise ValueError(f"{args.load_state} holds a {state['params'].get('mode')} estimate, not --mode {mode}")
        obj = args.object or ((state.get("run") or {}).get("object") if state else None)
        exp = Experiment(mode=mode, object_name=obj, strategy=args.strategy, alpha=args.alpha,
                         seed=args.seed, touches=args.touches, user_params_files=args.params, touch=args.touch)
        if state:  # the loaded estimator's parameters are the run's (report config, planner's view)
            exp.overrides["gpis_estimator"] = dict(state["params"])
        loop = ExplorationLoop(exp)
        if state:
            loop.estimator = build_estimator(state, args.load_state)[0]
            loaded = loop.estimator.n_observations
            print(f"loaded {loaded} observations from {args.load_state}", file=sys.stderr)
        if args.evaluate_only:
            report = make_report(exp.object_name, exp.mode, exp.strategy, exp.seed, exp.config_summary(), [],
                                 loop.evaluator.iou(loop.estimator), "evaluated a loaded state")
        else:
            print(f"exploring '{exp.object_name}' ({exp.mode}) with '{exp.strategy}', seed {exp.seed}, "
                  f"{exp.touches} touches", file=sys.stderr)
            progress = None if args.quiet else (lambda r: print(progress_line(r, exp.touches), file=sys.stderr))
            report = loop.run(progress)
        if state:
            report["loaded_state"] = {"path": str(args.load_state), "observations": loaded}
        check_report(report)
        if args.out:  # report.json first, then the exports and the figure
            write_outputs(report, loop.estimator, loop.evaluator, args.out, exp.mode)
        if not args.out or args.report:
            write_report(report, report_path)
        if args.shape:
            loop.estimator.export_shape(args.shape)
        if args.plot:
            plots.plot_progress(report, args.plot, loop.estimator.surface_points(), loop.true_surface,
                                estimator=loop.estimator, obj=loop.evaluator.obj)
        s = report["summary"]
        if args.evaluate_only:
            print(f"IoU {s['final_iou']:.3f} of the loaded estimate ({loop.estimator.n_observations} "
                  f"observations); report: {report_path}")
            return 0
        t90, t95 = s["travel_to_iou_0.90_m"], s["travel_to_iou_0.95_m"]
        print(f"final IoU {s['final_iou']:.3f} after {s['touches']} touches, travel {s['travel_m']:.2f} m, "
              f"time {s['time_s']:.0f} s; travel to IoU 0.90: {_m(t90)}, to 0.95: {_m(t95)} "
              f"({s['stopped_because']}); report: {report_path}")
        return 0

    return run_main(body)


def _m(v: Optional[float]) -> str:
    return "not reached" if v is None else f"{v:.2f} m"


if __name__ == "__main__":
    sys.exit(main())
