"""``tactile-benchmark``: strategies × objects × seeds, in parallel over the cores.

Writes to ``--out``: ``runs.json`` (every report), ``summary.md`` (per object
and strategy: median travel and time to IoU 0.90/0.95, final IoU, median
decision ms, and how many seeds reached each level), ``iou_vs_travel.png``,
``iou_vs_time.png`` and ``gallery.png`` (final estimates over the truth).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time
from functools import partial
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from . import plots
from .cli_common import Parser, add_experiment_args, integer, run_main
from .progress_bar import ProgressBar
from .sweep import failure_line, guarded, is_failure
from .experiment import Experiment
from .loop import ExplorationLoop
from .report import _clean

STRATEGIES = ("proposed", "uncertainty", "random", "sequential", "info_gain")


def _one_run(job: dict) -> dict:
    """Run one (object, strategy, seed); keep the final shapes for the gallery."""
    exp = Experiment(mode=job["mode"], object_name=job["object"], strategy=job["strategy"],
                     alpha=job["alpha"], seed=job["seed"], touches=job["touches"],
                     user_params_files=job["params"])
    loop = ExplorationLoop(exp)
    t0 = time.perf_counter()
    report = loop.run()
    report["wall_s"] = time.perf_counter() - t0
    est = loop.estimator.surface_points()
    report["_shape"] = (est[:, :2].tolist(), loop.true_surface[:, :2].tolist())
    return report


def _median(values: list) -> Optional[float]:
    vals = [v for v in values if v is not None]
    return float(np.median(vals)) if vals else None


def summary_table(runs: Sequence[dict]) -> str:
    """Markdown table: one row per object and strategy (medians over seeds)."""
    head = ("| object | strategy | seeds | final IoU | travel to 0.90 (m) | travel to 0.95 (m) "
            "| time to 0.95 (s) | reached 0.95 | decision (ms) | wall (s) |\n"
            "|---|---|---|---|---|---|---|---|---|---|\n")
    rows = []
    for obj in sorted({r["object"] for r in runs}):
        for strat in sorted({r["strategy"] for r in runs}):
            sel = [r for r in runs if r["object"] == obj and r["strategy"] == strat]
            if not sel:
                continue
            s = [r["summary"] for r in sel]
            t95 = [x["travel_to_iou_0.95_m"] for x in s]
            dec = [t["decision_ms"] for r in sel for t in r["touches"]]
            rows.append(
                f"| {obj} | {strat} | {len(sel)} | {_fmt(_median([x['final_iou'] for x in s]), 3)} "
                f"| {_fmt(_median([x['travel_to_iou_0.90_m'] for x in s]), 2)} | {_fmt(_median(t95), 2)} "
                f"| {_fmt(_median([x['time_to_iou_0.95_s'] for x in s]), 0)} "
                f"| {sum(v is not None for v in t95)}/{len(sel)} | {_fmt(_median(dec), 0)} "
                f"| {_fmt(max(r['wall_s'] for r in sel), 0)} |")
    return head + "\n".join(rows) + "\n"


def overall_table(runs: Sequence[dict], level: str = "0.95") -> str:
    """Per strategy over the whole suite: median travel/time to the level, counting
    a run that never reached it at its total travel/time (a lower bound on its cost)."""
    lines = [f"| strategy | runs | reached {level} | median travel to {level} (m)* | "
             f"median time to {level} (s)* | median final IoU |", "|---|---|---|---|---|---|"]
    for strat in sorted({r["strategy"] for r in runs}):
        sel = [r["summary"] for r in runs if r["strategy"] == strat]
        trav = [x[f"travel_to_iou_{level}_m"] if x[f"travel_to_iou_{level}_m"] is not None else x["travel_m"]
                for x in sel]
        tim = [x[f"time_to_iou_{level}_s"] if x[f"time_to_iou_{level}_s"] is not None else x["time_s"]
               for x in sel]
        reached = sum(x[f"travel_to_iou_{level}_m"] is not None for x in sel)
        lines.append(f"| {strat} | {len(sel)} | {reached}/{len(sel)} | {np.median(trav):.2f} | "
                     f"{np.median(tim):.0f} | {np.median([x['final_iou'] for x in sel]):.3f} |")
    return "\n".join(lines) + "\n\n*runs that never reached the level count with their whole travel/time.\n"


def iou_at_travel(report: dict, budget_m: float) -> float:
    """IoU of the estimate when the cumulative travel first stops being within ``budget_m``."""
    iou = report["summary"].get("prior_iou", 0.0)
    for t in report["touches"]:
        if t["travel_m"] > budget_m:
            break
        iou = t["iou"]
    return float(iou)


def budget_table(runs: Sequence[dict], budgets_m: Sequence[float] = (1.0, 1.5, 2.0, 3.0)) -> str:
    """Median IoU per strategy at equal travel budgets: the claim in one table
    (a run whose touch budget ended before a travel budget keeps its final IoU)."""
    lines = ["| strategy | " + " | ".join(f"IoU at {b:g} m" for b in budgets_m) + " | median travel of the run (m) |",
             "|---|" + "---|" * (len(budgets_m) + 1)]
    for strat in sorted({r["strategy"] for r in runs}):
        sel = [r for r in runs if r["strategy"] == strat]
        cells = [f"{np.median([iou_at_travel(r, b) for r in sel]):.3f}" for b in budgets_m]
        lines.append(f"| {strat} | " + " | ".join(cells) + f" | {np.median([r['summary']['travel_m'] for r in sel]):.2f} |")
    return "\n".join(lines) + "\n"


def write_summary(runs: Sequence[dict], out: Path, mode: str, shapes: Sequence = ()) -> str:
    """summary.md and the figures of a set of runs; the Markdown text."""
    touches = max(len(r["touches"]) for r in runs)
    seeds = len({r["seed"] for r in runs})
    md = (f"# Strategy benchmark ({mode}, up to {touches} touches, {seeds} seeds)\n\n"
          f"## Whole suite\n\n{overall_table(runs)}\n### IoU at equal travel\n\n{budget_table(runs)}\n"
          f"## Per object (medians over seeds)\n\n{summary_table(runs)}")
    (out / "summary.md").write_text(md)
    plots.plot_strategies(runs, out / "iou_vs_travel.png", "travel_m")
    plots.plot_strategies(runs, out / "iou_vs_time.png", "time_s")
    if shapes:
        plots.plot_gallery(sorted(shapes, key=lambda s: s[0]), out / "gallery.png")
    return md


def _fmt(v: Optional[float], digits: int) -> str:
    return "—" if v is None else f"{v:.{digits}f}"


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = Parser(prog="tactile-benchmark", description=__doc__.splitlines()[0])
    add_experiment_args(parser, several=True)
    parser.add_argument("--objects", default=None, help="comma-separated objects (default: all built-in)")
    parser.add_argument("--strategies", default=",".join(STRATEGIES), help="comma-separated strategies")
    parser.add_argument("--seeds", type=integer, default=5, help="seeds 0..N-1, N ≥ 1 (default 5)")
    parser.add_argument("--jobs", type=integer, default=os.cpu_count() or 1, help="parallel runs ≥ 1 (default: cores)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--from-runs", type=Path, default=None, metavar="RUNS_JSON",
                        help="no runs: rebuild summary.md and the plots of an earlier runs.json into --out")
    args = parser.parse_args(argv)

    def body() -> int:
        if args.from_runs:
            runs = json.loads(args.from_runs.read_text())
            if not runs:
                raise ValueError(f"{args.from_runs} holds no runs")
            args.out.mkdir(parents=True, exist_ok=True)
            print(write_summary(runs, args.out, runs[0]["mode"]))
            return 0
        from tactile_sim.objects import list_objects

        objects = args.objects.split(",") if args.objects else list_objects(args.mode)
        strategies = args.strategies.split(",")
        _check_args(args, objects, strategies)
        touches = args.touches
        if touches is None:
            touches = 30 if args.mode == "2d" else 60
        jobs = [dict(mode=args.mode, object=o, strategy=s, seed=seed, alpha=args.alpha,
                     touches=touches, params=[str(p) for p in args.params])
                for o in objects for s in strategies for seed in range(args.seeds)]
        # Fail fast on bad names before starting the pool.
        Experiment(mode=args.mode, object_name=objects[0], strategy=strategies[0], touches=1,
                   user_params_files=args.params)
        args.out.mkdir(parents=True, exist_ok=True)
        runs, shapes, t0 = [], [], time.time()
        print(f"{len(jobs)} runs ({len(objects)} objects × {len(strategies)} strategies × {args.seeds} seeds, "
              f"{touches} touches) on {args.jobs} processes", file=sys.stderr)
        # One BLAS thread per run: N runs on N cores with BLAS's own threads on top
        # oversubscribe the cores and doubled the wall time per run (measured, 3D).
        # BLAS reads these when it loads, so the workers are spawned, not forked.
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        ctx = mp.get_context("spawn")
        # A run that raises is reported (with the command that repeats it) and the sweep goes on.
        bar, failures = ProgressBar(len(jobs)), []
        with ctx.Pool(args.jobs, maxtasksperchild=4) as pool:
            for report in pool.imap_unordered(partial(guarded, _one_run), jobs):
                if is_failure(report):
                    failures.append(report)
                    bar.update(False, failure_line(report))
                    continue
                est, truth = report.pop("_shape")
                s = report["summary"]
                if report["seed"] == 0:
                    shapes.append((f"{report['object']} / {report['strategy']}\nIoU {s['final_iou']:.3f}",
                                   np.asarray(est), np.asarray(truth)))
                runs.append(report)
                bar.update(True, f"{report['object']:>14s} {report['strategy']:>11s} seed {report['seed']}: "
                           f"IoU {s['final_iou']:.3f}, travel to 0.95 "
                           f"{'—' if s['travel_to_iou_0.95_m'] is None else format(s['travel_to_iou_0.95_m'], '.2f')} m, "
                           f"{report['wall_s']:.0f} s")
        bar.close()
        if failures:
            (args.out / "failures.json").write_text(json.dumps(_clean(failures), indent=1))
            print(f"{len(failures)} of {len(jobs)} runs failed (details: {args.out}/failures.json):", file=sys.stderr)
            for f in failures:
                print(failure_line(f), file=sys.stderr)
        if not runs:
            print("no run finished: no summary", file=sys.stderr)
            return 1
        runs.sort(key=lambda r: (r["object"], r["strategy"], r["seed"]))
        (args.out / "runs.json").write_text(json.dumps(_clean(runs)))
        print(write_summary(runs, args.out, args.mode, shapes))
        print(f"wrote {args.out}/runs.json, summary.md, iou_vs_travel.png, iou_vs_time.png, gallery.png",
              file=sys.stderr)
        return 1 if failures else 0

    return run_main(body)


def _check_args(args: argparse.Namespace, objects: Sequence[str], strategies: Sequence[str]) -> None:
    """Every value before the pool starts (one line per problem, exit 2): the counts, each
    strategy against the planner's rule, each object name or file."""
    from tactile_sim.objects import make_object

    from .param_checks import ParamsError, check_cli, param_spec

    errors = [f"--{k} {v}: must be ≥ 1" for k, v in (("seeds", args.seeds), ("jobs", args.jobs)) if v < 1]
    if args.touches is not None and check_cli("--touches", args.touches):
        errors.append(check_cli("--touches", args.touches))
    allowed = param_spec("soc_planner", "strategy").rule.choices
    errors += [f"--strategies: unknown strategy '{s}' (one of {', '.join(allowed)})" for s in strategies
               if s not in allowed]
    for o in objects:
        try:
            make_object(o, mode=args.mode)
        except ValueError as exc:
            errors.append(f"--objects: {exc}")
    if errors:
        raise ParamsError(errors)


if __name__ == "__main__":
    sys.exit(main())
