"""``tactile-explore-offline``: one exploration in simulation without ROS.

Example::

    tactile-explore-offline --object star --mode 2d --strategy proposed --touches 30 \\
        --seed 1 --report out.json --plot out.png
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional, Sequence

from . import plots
from .cli_common import Parser, add_experiment_args, progress_line, run_main
from .experiment import Experiment
from .loop import ExplorationLoop
from .report import check_report, write_report


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = Parser(prog="tactile-explore-offline", description=__doc__.splitlines()[0])
    add_experiment_args(parser)
    parser.add_argument("--report", type=Path, default=Path("report.json"), help="report JSON path")
    parser.add_argument("--plot", type=Path, default=None, help="progress figure (PNG)")
    parser.add_argument("--shape", type=Path, default=None, help="export the estimate (.csv 2D, .ply/.stl 3D)")
    parser.add_argument("--quiet", action="store_true", help="no per-touch progress")
    args = parser.parse_args(argv)

    def body() -> int:
        exp = Experiment(mode=args.mode, object_name=args.object, strategy=args.strategy, alpha=args.alpha,
                         seed=args.seed, touches=args.touches, user_params_files=args.params, touch=args.touch)
        loop = ExplorationLoop(exp)
        print(f"exploring '{exp.object_name}' ({exp.mode}) with '{exp.strategy}', seed {exp.seed}, "
              f"{exp.touches} touches", file=sys.stderr)
        progress = None if args.quiet else (lambda r: print(progress_line(r, exp.touches), file=sys.stderr))
        report = loop.run(progress)
        check_report(report)
        write_report(report, args.report)
        if args.shape:
            loop.estimator.export_shape(args.shape)
        if args.plot:
            plots.plot_progress(report, args.plot, loop.estimator.surface_points(), loop.true_surface,
                                estimator=loop.estimator, obj=loop.evaluator.obj)
        s = report["summary"]
        t90, t95 = s["travel_to_iou_0.90_m"], s["travel_to_iou_0.95_m"]
        print(f"final IoU {s['final_iou']:.3f} after {s['touches']} touches, travel {s['travel_m']:.2f} m, "
              f"time {s['time_s']:.0f} s; travel to IoU 0.90: {_m(t90)}, to 0.95: {_m(t95)} "
              f"({s['stopped_because']}); report: {args.report}")
        return 0

    return run_main(body)


def _m(v: Optional[float]) -> str:
    return "not reached" if v is None else f"{v:.2f} m"


if __name__ == "__main__":
    sys.exit(main())
