"""Command-line pieces shared by the offline explorer and the benchmark."""

from __future__ import annotations

import argparse
import sys
from typing import Callable


def add_experiment_args(parser: argparse.ArgumentParser, several: bool = False) -> None:
    """--mode, --params, and (single run) --object/--strategy/--alpha/--seed/--touches."""
    parser.add_argument("--mode", choices=("2d", "3d"), default="2d", help="2d contour or 3d surface (default 2d)")
    parser.add_argument("--params", action="append", default=[], metavar="FILE",
                        help="ROS parameter file overriding node parameters (repeatable)")
    parser.add_argument("--touches", type=int, default=None, help="touch budget (default: explorer.yaml)")
    parser.add_argument("--alpha", type=float, default=None, help="uncertainty/travel trade-off of 'proposed'")
    if not several:
        parser.add_argument("--object", default=None, help="object name or file (.csv 2D polygon, .stl/.obj mesh)")
        parser.add_argument("--strategy", default=None,
                            help="proposed | uncertainty | random | sequential | info_gain (default proposed)")
        parser.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")


def progress_line(record: dict, total: int) -> str:
    err = record["surface_error_m"]
    err_txt = f"{err * 1000:5.1f} mm" if err is not None else "   n/a"
    return (f"touch {record['index'] + 1:3d}/{total}  {record['outcome']:10s}  "
            f"travel {record['travel_m']:6.3f} m  time {record['time_s']:6.1f} s  "
            f"IoU {record['iou']:.3f}  surface error {err_txt}  decision {record['decision_ms']:5.0f} ms")


def run_main(body: Callable[[], int]) -> int:
    """Run ``body``; bad input ends with a message and status 2, Ctrl-C with 130."""
    try:
        return body()
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
