"""Command-line pieces shared by the offline explorer, the benchmark and the launch plan.

Values are parsed here (an integer, a finite number) and then checked against
the rule of the node parameter they set (``param_checks.CLI_OPTIONS``), so the
command line and a parameter file accept exactly the same values.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path
from typing import Callable, Optional

from tactile_planner.strategies import STRATEGY_NAMES


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line (``prog: error: ... (see --help)``), status 2."""

    def error(self, message: str):  # noqa: D102 - argparse's hook
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def finite_float(text: str) -> float:
    """A finite number (``nan`` and ``inf`` are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not a finite number")
    return value


def integer(text: str) -> int:
    """An integer (``2.5`` and ``abc`` are refused with the value in the message)."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None


def add_experiment_args(parser: argparse.ArgumentParser, several: bool = False) -> None:
    """--mode, --params, and (single run) --object/--strategy/--alpha/--seed/--touches."""
    parser.add_argument("--mode", choices=("2d", "3d"), default="2d", help="2d contour or 3d surface (default 2d)")
    parser.add_argument("--params", action="append", default=[], metavar="FILE",
                        help="ROS parameter file overriding node parameters (repeatable)")
    parser.add_argument("--touches", type=integer, default=None, help="touch budget ≥ 1 (default: explorer.yaml)")
    parser.add_argument("--alpha", type=finite_float, default=None,
                        help="uncertainty/travel trade-off of 'proposed' (≥ 0)")
    if not several:
        parser.add_argument("--object", default=None, help="object name or file (.csv 2D polygon, .stl/.obj mesh)")
        parser.add_argument("--strategy", default=None,
                            help=" | ".join(STRATEGY_NAMES) + " (default: soc_planner.yaml's strategy)")
        parser.add_argument("--seed", type=integer, default=0, help="seed of every random choice, ≥ 0 (default 0)")
    parser.add_argument("--touch", default=None, metavar="poke|slide",
                        help="poke: approach and retract; slide: approach, then follow the surface "
                             "(soc_planner.touch; default poke)")


def progress_line(record: dict, total: int) -> str:
    err = record["surface_error_m"]
    err_txt = f"{err * 1000:5.1f} mm" if err is not None else "   n/a"
    return (f"touch {record['index'] + 1:3d}/{total}  {record['outcome']:10s}  "
            f"travel {record['travel_m']:6.3f} m  time {record['time_s']:6.1f} s  "
            f"IoU {record['iou']:.3f}  surface error {err_txt}  decision {record['decision_ms']:5.0f} ms")


def output_problem(path: Path, option: str, folder: bool = False) -> Optional[str]:
    """Why ``path`` cannot be written (None when it can), checked before any work: a file output
    that is a folder, a folder output that is a file, or a nearest existing parent that is not a
    folder one can write in (tried with a temporary file; missing folders below it are created
    when the output is written)."""
    path = Path(path)
    if path.exists() and path.is_dir() != folder:
        return f"{option} {path}: is {'a file' if folder else 'a folder'}"
    parent = path if folder and path.exists() else path.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        return f"{option} {path}: {parent} is not a folder"
    try:  # a real write (root passes every permission check; a read-only or virtual file system does not)
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        return f"{option} {path}: cannot write in {parent} ({exc.strerror or exc})"
    return None


def check_outputs(*outputs: tuple[Optional[Path], str, bool]) -> None:
    """Raise ValueError (one line per problem) for any ``(path, option, folder)`` that
    :func:`output_problem` refuses; a None path is not asked for."""
    problems = [output_problem(path, option, folder) for path, option, folder in outputs if path is not None]
    if any(problems):
        raise ValueError("\n".join(p for p in problems if p))


def run_main(body: Callable[[], int]) -> int:
    """Run ``body``; bad input ends with a message and status 2, an I/O error with one line and
    status 1, Ctrl-C with 130."""
    try:
        return body()
    except ValueError as exc:  # one line per problem (a ParamsError may hold several)
        for line in str(exc).splitlines() or [type(exc).__name__]:
            print(f"error: {line}", file=sys.stderr)
        return 2
    except OSError as exc:  # a disk, a permission, a path that changed under us: no traceback
        where = f": {exc.filename}" if exc.filename else ""
        print(f"error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
