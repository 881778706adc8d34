"""``tactile-benchmark``: strategies × objects × seeds, in parallel over the cores.

Objects: the built-in catalogue (``--suite builtin``, default) or the seeded
generated suite (``--suite generated --count N --seed S``:
:mod:`tactile_sim.generated`), or ``--objects``.

Writes to ``--out``: ``runs.json`` (every report), ``summary.md``,
``iou_vs_travel.png``, ``iou_vs_time.png`` and ``gallery.png`` (final
estimates over the truth). ``summary.md`` has two parts, each table saying
which IoU it shows: the **raw IoU** (against the true solid: whole suite,
IoU at equal travel, per object) and the **reachable IoU** (against the
finger-reachable solid, :func:`tactile_sim.metrics.reachable_inside`):
whole suite, the default strategy's travel and time ratios against
``uncertainty``, ``random`` and ``sequential`` (geometric mean over
objects), per family and per object (medians over seeds) of travel and
robot time to 0.90/0.95 and the final value, and the objects that end
below the target.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from . import plots
from .cli_common import Parser, add_experiment_args, check_outputs, integer, run_main
from .progress_bar import ProgressBar
from .sweep import failure_line, is_failure
from .sweep_backends import cluster_address, dask_cluster, local_pool
from .sweep_log import LOG_NAME, SweepLog, job_key
from .experiment import Experiment
from .loop import ExplorationLoop
from .report import _clean

STRATEGIES = ("proposed", "uncertainty", "random", "sequential", "info_gain")


def _one_run(job: dict) -> dict:
    """Run one (object, strategy, seed); keep the final shapes for the gallery.

    The job carries the text of its parameter files and the bytes of an object file
    (``params_text``, ``object_file``): they are written to a private folder here, so a
    worker on another machine needs no shared disk, and a file edited while the sweep
    runs does not change the runs still to come.
    """
    with tempfile.TemporaryDirectory(prefix="tactile-run-") as tmp:
        params, named = job["params"], {}  # named: private copy -> the user's name (for the report)
        if job.get("params_text") is not None:
            params = []
            for i, (path, text) in enumerate(zip(job["params"], job["params_text"])):
                params.append(Path(tmp) / f"{i}-{Path(path).name}")
                params[-1].write_text(text)
                named[str(params[-1])] = str(path)
        obj = job["object"]
        if job.get("object_file") is not None:
            obj = str(Path(tmp) / f"object{Path(obj).suffix}")
            Path(obj).write_bytes(job["object_file"])
            named[obj] = job["object"]
        exp = Experiment(mode=job["mode"], object_name=obj, strategy=job["strategy"],
                         alpha=job["alpha"], seed=job["seed"], touches=job["touches"],
                         user_params_files=params, touch=job.get("touch"))
        loop = ExplorationLoop(exp)
        t0 = time.perf_counter()
        report = loop.run()
    report = _renamed(report, named)
    report["wall_s"] = time.perf_counter() - t0
    report["touch"] = loop.touch  # poke | slide; 2D: travel in laps of this contour (tactile_bringup.slide_tables)
    if exp.mode == "2d":
        from tactile_sim.contour import contour_length_m

        report["contour_length_m"] = contour_length_m(loop.evaluator.obj)
    if job["seed"] == 0:  # the gallery draws seed 0
        est = loop.estimator.surface_points()
        report["_shape"] = (est[:, :2].tolist(), loop.true_surface[:, :2].tolist())
    return report


def _renamed(value, names: dict):
    """``value`` with every string that is a key of ``names`` replaced by its value (nested)."""
    if isinstance(value, str):
        return names.get(value, value)
    if isinstance(value, dict):
        return {k: _renamed(v, names) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_renamed(v, names) for v in value)
    return value


def make_jobs(mode: str, objects: Sequence[str], strategies: Sequence[str], seeds: int, touches: int,
              alpha: Optional[float], params: Sequence[Path], touch: Optional[str]) -> list[dict]:
    """One job per (object, strategy, seed), carrying its parameter files' text and an
    object file's bytes (see :func:`_one_run`) and its key in the sweep log."""
    params_text = [Path(p).read_text() for p in params]
    jobs = []
    for o in objects:
        obj_file = Path(o).read_bytes() if Path(o).is_file() else None
        for st in strategies:
            for seed in range(seeds):
                job = dict(mode=mode, object=o, strategy=st, seed=seed, alpha=alpha, touches=touches,
                           params=[str(p) for p in params], params_text=params_text, touch=touch,
                           object_file=obj_file)
                job["key"] = job_key(job)
                jobs.append(job)
    return jobs


def _median(values: list) -> Optional[float]:
    vals = [v for v in values if v is not None]
    return float(np.median(vals)) if vals else None


def summary_table(runs: Sequence[dict]) -> str:
    """Markdown table, raw IoU: one row per object and strategy (medians over seeds)."""
    head = ("| object | strategy | seeds | final raw IoU | travel to raw 0.90 (m) | travel to raw 0.95 (m) "
            "| time to raw 0.95 (s) | reached raw 0.95 | decision (ms) | wall (s) |\n"
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
    """Raw IoU, per strategy over the whole suite: median travel/time to the level, counting
    a run that never reached it at its total travel/time (a lower bound on its cost)."""
    lines = [f"| strategy | runs | reached raw {level} | median travel to raw {level} (m)* | "
             f"median time to raw {level} (s)* | median final raw IoU |", "|---|---|---|---|---|---|"]
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
    lines = ["| strategy | " + " | ".join(f"raw IoU at {b:g} m" for b in budgets_m) + " | median travel of the run (m) |",
             "|---|" + "---|" * (len(budgets_m) + 1)]
    for strat in sorted({r["strategy"] for r in runs}):
        sel = [r for r in runs if r["strategy"] == strat]
        cells = [f"{np.median([iou_at_travel(r, b) for r in sel]):.3f}" for b in budgets_m]
        lines.append(f"| {strat} | " + " | ".join(cells) + f" | {np.median([r['summary']['travel_m'] for r in sel]):.2f} |")
    return "\n".join(lines) + "\n"


# -- reachable IoU tables ----------------------------------------------------------
#: The strategy the ratios are taken for, and those it is compared with.
DEFAULT_STRATEGY = "proposed"
BASELINES = ("uncertainty", "random", "sequential")
TARGET_IOU = 0.95
_LEVELS = ("0.90", "0.95")


def default_strategy(runs: Sequence[dict]) -> str:
    """The strategy the ratios are for: the mode's default (``info_travel``; per second in 3D; from the
    configuration files), when the runs hold it; else ``DEFAULT_STRATEGY``."""
    have = {r["strategy"] for r in runs}
    try:
        mode_default = Experiment(mode=str(runs[0].get("mode", "2d"))).strategy
    except (ValueError, KeyError, IndexError):
        return DEFAULT_STRATEGY
    return mode_default if mode_default in have else DEFAULT_STRATEGY


def family_of(name: str) -> str:
    """A generated object's family (``gen2d-017-letter_H`` → ``letter_H``); ``builtin`` otherwise."""
    from tactile_sim.generated import is_generated_name, parse_name

    return parse_name(name)[3] if is_generated_name(name) else "builtin"


def has_reachable(runs: Sequence[dict]) -> bool:
    """Whether the runs carry the reachable IoU (runs.json files written before it do not)."""
    return any(r["summary"].get("final_iou_reachable") is not None for r in runs)


def _cost(summary: dict, what: str, level: str) -> tuple[float, bool]:
    """(travel [m] or time [s] to reachable IoU ``level``, reached?); a run that never
    reached it counts with its whole travel/time (a lower bound of its cost)."""
    unit = "m" if what == "travel" else "s"
    v = summary.get(f"{what}_to_iou_reachable_{level}_{unit}")
    return (float(v), True) if v is not None else (float(summary[f"{what}_{unit}"]), False)


def _per_object(runs: Sequence[dict]) -> dict:
    """{(object, strategy): medians over seeds of the reachable-IoU costs} (censored, see _cost)."""
    out: dict = {}
    for key in sorted({(r["object"], r["strategy"]) for r in runs}):
        sel = [r["summary"] for r in runs if (r["object"], r["strategy"]) == key]
        row = {"seeds": len(sel), "final": _median([x.get("final_iou_reachable") for x in sel])}
        for what in ("travel", "time"):
            for level in _LEVELS:
                vals = [_cost(x, what, level) for x in sel]
                row[(what, level)] = float(np.median([v for v, _ in vals]))
                row[(what, level, "reached")] = sum(ok for _, ok in vals)
                # The median run reached the level when more than half the seeds did.
                row[(what, level, "median_reached")] = 2 * row[(what, level, "reached")] > len(sel)
        out[key] = row
    return out


def _cell(row: dict, what: str, level: str, digits: int) -> str:
    v = row[(what, level)]
    return f"{v:.{digits}f}" if row[(what, level, "median_reached")] else f"≥{v:.{digits}f}"


def reachable_overall_table(runs: Sequence[dict]) -> str:
    """Reachable IoU, per strategy over the whole suite (censored medians over runs)."""
    lines = ["| strategy | runs | reached reach. 0.90 | reached reach. 0.95 | travel to reach. 0.95 (m)* "
             "| time to reach. 0.95 (s)* | median final reachable IoU |", "|---|---|---|---|---|---|---|"]
    for strat in sorted({r["strategy"] for r in runs}):
        sel = [r["summary"] for r in runs if r["strategy"] == strat]
        n90 = sum(_cost(x, "travel", "0.90")[1] for x in sel)
        n95 = sum(_cost(x, "travel", "0.95")[1] for x in sel)
        trav = np.median([_cost(x, "travel", "0.95")[0] for x in sel])
        tim = np.median([_cost(x, "time", "0.95")[0] for x in sel])
        lines.append(f"| {strat} | {len(sel)} | {n90}/{len(sel)} | {n95}/{len(sel)} | {trav:.2f} | {tim:.0f} "
                     f"| {_fmt(_median([x.get('final_iou_reachable') for x in sel]), 3)} |")
    return "\n".join(lines) + "\n"


def ratio_table(runs: Sequence[dict], default: str = DEFAULT_STRATEGY, baselines: Sequence[str] = BASELINES) -> str:
    """Reachable IoU: the default strategy's cost over each baseline's, geometric mean over objects.

    Per object the ratio of the medians over seeds (censored, see :func:`_cost`):
    < 1 means the default strategy needs less. "both reached" keeps only the
    objects where both median runs reached the level (an uncensored ratio).
    """
    per = _per_object(runs)
    objects = sorted({o for o, _ in per})
    lines = [f"| {default} vs | travel to reach. 0.90 | travel to reach. 0.95 | time to reach. 0.90 "
             "| time to reach. 0.95 | objects (both reached 0.90 / 0.95) | travel 0.95, both reached |",
             "|---|---|---|---|---|---|---|"]
    for base in baselines:
        pairs = [(per[(o, default)], per[(o, base)]) for o in objects if (o, default) in per and (o, base) in per]
        if not pairs:
            continue
        cells = []
        for what, level in (("travel", "0.90"), ("travel", "0.95"), ("time", "0.90"), ("time", "0.95")):
            cells.append(f"{_geomean([a[(what, level)] / b[(what, level)] for a, b in pairs]):.2f}")
        both = {lv: [(a, b) for a, b in pairs if a[("travel", lv, "median_reached")] and b[("travel", lv, "median_reached")]]
                for lv in _LEVELS}
        strict = both["0.95"]
        strict_txt = f"{_geomean([a[('travel', '0.95')] / b[('travel', '0.95')] for a, b in strict]):.2f}" if strict else "—"
        lines.append(f"| {base} | " + " | ".join(cells)
                     + f" | {len(pairs)} ({len(both['0.90'])} / {len(strict)}) | {strict_txt} |")
    return ("\n".join(lines) + "\n\nRatios < 1: the default strategy needs less travel/time. Runs that never reached "
            "the level count with their whole travel/time (a lower bound of their cost).\n")


def _geomean(values: Sequence[float]) -> float:
    v = np.asarray([x for x in values if x > 0], dtype=float)
    return float(np.exp(np.mean(np.log(v)))) if len(v) else float("nan")


def family_table(runs: Sequence[dict]) -> str:
    """Reachable IoU, per family and strategy: medians over objects of the per-object medians."""
    per = _per_object(runs)
    lines = ["| family | strategy | objects | travel to reach. 0.90 (m)* | travel to reach. 0.95 (m)* "
             "| time to reach. 0.90 (s)* | time to reach. 0.95 (s)* | objects reaching 0.95 | final reachable IoU |",
             "|---|---|---|---|---|---|---|---|---|"]
    fams = sorted({family_of(o) for o, _ in per})
    for fam in fams:
        for strat in sorted({st for _, st in per}):
            rows = [v for (o, st), v in per.items() if st == strat and family_of(o) == fam]
            if not rows:
                continue
            med = {k: float(np.median([r[k] for r in rows])) for k in
                   [("travel", "0.90"), ("travel", "0.95"), ("time", "0.90"), ("time", "0.95")]}
            n95 = sum(r[("travel", "0.95", "median_reached")] for r in rows)
            lines.append(f"| {fam} | {strat} | {len(rows)} | {med[('travel', '0.90')]:.2f} | {med[('travel', '0.95')]:.2f} "
                         f"| {med[('time', '0.90')]:.0f} | {med[('time', '0.95')]:.0f} | {n95}/{len(rows)} "
                         f"| {_fmt(_median([r['final'] for r in rows]), 3)} |")
    return "\n".join(lines) + "\n"


def reachable_object_table(runs: Sequence[dict]) -> str:
    """Reachable IoU, per object and strategy (medians over seeds; "≥": the median run did not reach)."""
    per = _per_object(runs)
    lines = ["| object | family | strategy | seeds | final reachable IoU | travel to reach. 0.90 (m) "
             "| travel to reach. 0.95 (m) | time to reach. 0.90 (s) | time to reach. 0.95 (s) | reached reach. 0.95 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for (obj, strat), row in per.items():
        lines.append(f"| {obj} | {family_of(obj)} | {strat} | {row['seeds']} | {_fmt(row['final'], 3)} "
                     f"| {_cell(row, 'travel', '0.90', 2)} | {_cell(row, 'travel', '0.95', 2)} "
                     f"| {_cell(row, 'time', '0.90', 0)} | {_cell(row, 'time', '0.95', 0)} "
                     f"| {row[('travel', '0.95', 'reached')]}/{row['seeds']} |")
    return "\n".join(lines) + "\n"


def below_target(runs: Sequence[dict], target: float = TARGET_IOU) -> str:
    """Objects whose median final reachable IoU ends below ``target``, per strategy (worst first)."""
    per = _per_object(runs)
    lines = []
    for strat in sorted({st for _, st in per}):
        low = sorted(((row["final"], o) for (o, st), row in per.items()
                      if st == strat and row["final"] is not None and row["final"] < target))
        txt = ", ".join(f"{o} ({v:.3f})" for v, o in low) if low else "none"
        lines.append(f"- **{strat}** ({len(low)} of {sum(st == strat for _, st in per)}): {txt}")
    return "\n".join(lines) + "\n"


#: how far the final reachable IoU may fall below the run's best (issue 13's 3D criterion)
DROP_TOLERANCE = 0.01


def drop_table(runs: Sequence[dict], tolerance: float = DROP_TOLERANCE) -> str:
    """Per strategy: runs whose final reachable IoU ends more than ``tolerance`` below the best the
    run had reached (``drop_from_best_reachable``: more data made the estimate worse), and the
    worst of them. Runs without it (no reachable IoU, or written before it existed) are left out."""
    lines = [f"| strategy | runs | ending > {tolerance:g} below their best | worst: object, seed (best → final) |",
             "|---|---|---|---|"]
    for strat in sorted({r["strategy"] for r in runs}):
        sel = [r for r in runs if r["strategy"] == strat and r["summary"].get("drop_from_best_reachable") is not None]
        if not sel:
            continue
        bad = [r for r in sel if r["summary"]["drop_from_best_reachable"] > tolerance]
        worst = "—"
        if bad:
            w = max(bad, key=lambda r: r["summary"]["drop_from_best_reachable"])
            worst = (f"{w['object']}, {w['seed']} ({w['summary']['best_iou_reachable']:.3f} → "
                     f"{w['summary']['final_iou_reachable']:.3f})")
        lines.append(f"| {strat} | {len(sel)} | {len(bad)} | {worst} |")
    return "\n".join(lines) + "\n"


def reachable_sections(runs: Sequence[dict]) -> str:
    """The reachable-IoU part of summary.md (empty note for runs without it)."""
    if not has_reachable(runs):
        return "## Reachable IoU\n\nThese runs carry no reachable IoU (written before it existed).\n"
    default = default_strategy(runs)
    return (f"## Reachable IoU: whole suite\n\nIoU against the finger-reachable solid (the true solid closed by "
            f"a ball of the tip radius; in 3D counted above the lowest tip-centre height).\n\n"
            f"{reachable_overall_table(runs)}\n*censored: a run that never reached the level counts with its "
            f"whole travel/time.\n\n"
            f"### Reachable IoU: {default} against the baselines (geometric mean over objects)\n\n"
            f"{ratio_table(runs, default)}\n"
            f"### Reachable IoU: per family (medians over objects of the medians over seeds)\n\n{family_table(runs)}\n"
            f"### Objects ending below reachable IoU {TARGET_IOU:.2f} (median over seeds)\n\n{below_target(runs)}\n"
            f"### Runs that end worse than they were (reachable IoU, best seen in the run − final)\n\n"
            f"{drop_table(runs)}\n"
            f"### Reachable IoU: per object (medians over seeds)\n\n{reachable_object_table(runs)}")


def write_summary(runs: Sequence[dict], out: Path, mode: str, shapes: Sequence = ()) -> str:
    """summary.md and the figures of a set of runs; the Markdown text."""
    touches = max(len(r["touches"]) for r in runs)
    seeds = len({r["seed"] for r in runs})
    md = (f"# Strategy benchmark ({mode}, up to {touches} touches, {seeds} seeds)\n\n"
          f"## Whole suite (raw IoU)\n\n{overall_table(runs)}\n### Raw IoU at equal travel\n\n{budget_table(runs)}\n"
          f"{reachable_sections(runs)}\n"
          f"## Per object (raw IoU, medians over seeds)\n\n{summary_table(runs)}")
    (out / "summary.md").write_text(md)
    # panels per family for a generated suite, per object for the catalogue
    panel = (lambda r: family_of(r["object"])) if any(family_of(r["object"]) != "builtin" for r in runs) \
        else plots.group_key
    plots.plot_strategies(runs, out / "iou_vs_travel.png", "travel_m", group=panel)
    plots.plot_strategies(runs, out / "iou_vs_time.png", "time_s", group=panel)
    if all(plots.iou_keys(r) == ["iou", "iou_reachable"] for r in runs):
        plots.plot_strategies(runs, out / "iou_reachable_vs_travel.png", "travel_m", "iou_reachable", panel)
        plots.plot_strategies(runs, out / "iou_reachable_vs_time.png", "time_s", "iou_reachable", panel)
    if shapes:
        plots.plot_gallery(sorted(shapes, key=lambda s: s[0]), out / "gallery.png",
                           cols=len({r["strategy"] for r in runs}))  # one object per row
    return md


def _fmt(v: Optional[float], digits: int) -> str:
    return "—" if v is None else f"{v:.{digits}f}"


def suite_objects(mode: str, suite: str = "builtin", count: Optional[int] = None, seed: int = 0) -> list[str]:
    """The object names of a suite: the built-in catalogue or the first ``count`` generated objects."""
    from tactile_sim import generated
    from tactile_sim.objects import list_objects

    if suite == "builtin":
        return list_objects(mode)
    if suite != "generated":
        raise ValueError(f"--suite {suite}: must be builtin or generated")
    if count is None:
        count = 3 * len(generated.FAMILIES_2D if mode == "2d" else generated.FAMILIES_3D)
    if count < 1:
        raise ValueError(f"--count {count}: must be ≥ 1")
    if seed < 0:
        raise ValueError(f"--seed {seed}: must be ≥ 0")
    return generated.suite_names(mode, int(count), int(seed))


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = Parser(prog="tactile-benchmark", description=__doc__.splitlines()[0])
    add_experiment_args(parser, several=True)
    parser.add_argument("--objects", default=None,
                        help="comma-separated objects (default: every object of --suite)")
    parser.add_argument("--suite", choices=("builtin", "generated"), default="builtin",
                        help="builtin: the catalogue (default); generated: the seeded suite of tactile_sim.generated")
    parser.add_argument("--count", type=integer, default=None,
                        help="objects of the generated suite, ≥ 1 (default 33 in 2D, 30 in 3D: every family 3 times)")
    parser.add_argument("--seed", type=integer, default=0,
                        help="seed of the generated suite, ≥ 0 (default 0; the same seed gives the same objects)")
    parser.add_argument("--strategies", default=",".join(STRATEGIES), help="comma-separated strategies")
    parser.add_argument("--seeds", type=integer, default=5, help="seeds 0..N-1, N ≥ 1 (default 5)")
    parser.add_argument("--jobs", type=integer, default=None,
                        help="parallel local runs ≥ 1 (default: the cores; not with --cluster)")
    parser.add_argument("--cluster", default=None, metavar="ADDRESS",
                        help="run on the Dask scheduler at ADDRESS (tcp://HOST:PORT) instead of local processes; "
                             "its workers need this tree installed (docs/benchmarks.md, 'Sweeps')")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder; a sweep started again into it runs only the runs it lacks")
    parser.add_argument("--from-runs", type=Path, default=None, metavar="RUNS_JSON",
                        help="no runs: rebuild summary.md and the plots of an earlier runs.json "
                             "(or a sweep's runs.jsonl) into --out")
    args = parser.parse_args(argv)

    def body() -> int:
        check_outputs((args.out, "--out", True))
        if args.from_runs:
            runs = load_runs(args.from_runs)
            args.out.mkdir(parents=True, exist_ok=True)
            print(write_summary(runs, args.out, runs[0]["mode"]))
            return 0
        objects = args.objects.split(",") if args.objects else suite_objects(args.mode, args.suite, args.count, args.seed)
        strategies = args.strategies.split(",")
        _check_args(args, objects, strategies)
        touches = args.touches
        if touches is None:
            touches = 30 if args.mode == "2d" else 60
        jobs = make_jobs(args.mode, objects, strategies, args.seeds, touches, args.alpha, args.params, args.touch)
        # Fail fast on bad names before starting the pool.
        Experiment(mode=args.mode, object_name=objects[0], strategy=strategies[0], touches=1,
                   user_params_files=args.params)
        args.out.mkdir(parents=True, exist_ok=True)
        log = SweepLog(args.out / LOG_NAME)
        todo = log.pending(jobs)
        _say_resume(log, jobs, todo)
        where = f"the Dask cluster at {cluster_address(args.cluster)}" if args.cluster else \
            f"{args.jobs or os.cpu_count() or 1} processes"
        print(f"{len(jobs)} runs ({len(objects)} objects × {len(strategies)} strategies × {args.seeds} seeds, "
              f"{touches} touches), {len(todo)} to run on {where}", file=sys.stderr)
        failures = _run_jobs(todo, log, args) if todo else []
        if failures is None:  # interrupted
            print(f"interrupted: {len(log.reports_of(jobs))} of {len(jobs)} runs kept in {log.path}; "
                  "the same command goes on from there", file=sys.stderr)
            return 130
        if failures:
            (args.out / "failures.json").write_text(json.dumps(_clean(failures), indent=1))
            print(f"{len(failures)} of {len(jobs)} runs failed (details: {args.out}/failures.json):", file=sys.stderr)
            for f in failures:
                print(failure_line(f), file=sys.stderr)
        runs = [dict(r) for r in log.reports_of(jobs)]
        shapes = []
        for report in runs:
            shape = report.pop("_shape", None)
            if shape is not None:
                shapes.append((f"{report['object']} / {report['strategy']}\nIoU {report['summary']['final_iou']:.3f}",
                               np.asarray(shape[0]), np.asarray(shape[1])))
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


def load_runs(path: Path) -> list[dict]:
    """The reports of a ``runs.json`` (a list), or of a sweep log ``runs.jsonl`` (every run it holds)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"--from-runs {path}: no such file")
    if path.suffix == ".jsonl":
        runs = list(SweepLog(path).reports.values())
    else:
        try:
            runs = json.loads(path.read_text())
        except ValueError as exc:
            raise ValueError(f"--from-runs {path}: not a runs.json of tactile-benchmark ({exc})") from None
    if not isinstance(runs, list) or not all(isinstance(r, dict) and "summary" in r for r in runs):
        raise ValueError(f"--from-runs {path}: not a runs.json of tactile-benchmark (a list of reports)")
    if not runs:
        raise ValueError(f"--from-runs {path}: holds no runs")
    return [{k: v for k, v in r.items() if k != "_shape"} for r in runs]


def _say_resume(log: SweepLog, jobs: Sequence[dict], todo: Sequence[dict]) -> None:
    """What an earlier sweep into the same folder left: kept runs, cut lines, other settings."""
    if log.cut_lines:
        print(f"{log.path}: {log.cut_lines} unreadable line(s) (cut by a crash?) ignored; "
              "those runs are made again", file=sys.stderr)
    kept = len(jobs) - len(todo)
    if kept:
        print(f"resuming: {kept} of {len(jobs)} runs already in {log.path} (delete it to make them again)",
              file=sys.stderr)
    others = log.others(jobs)
    if others:
        print(f"{log.path}: {others} run(s) of other settings left out of this summary", file=sys.stderr)


def _run_line(report: dict) -> str:
    s = report["summary"]
    t95 = s["travel_to_iou_0.95_m"]
    return (f"{report['object']:>14s} {report['strategy']:>11s} seed {report['seed']}: IoU {s['final_iou']:.3f}, "
            f"travel to 0.95 {'—' if t95 is None else format(t95, '.2f')} m, {report['wall_s']:.0f} s")


def _run_jobs(todo: Sequence[dict], log: SweepLog, args: argparse.Namespace) -> Optional[list[dict]]:
    """Run the jobs locally or on the cluster, each result into the log as it comes; the
    failures (a run that raises is reported with the command that repeats it, and the
    sweep goes on), or None when interrupted (Ctrl-C)."""
    if args.cluster:
        results = dask_cluster(todo, _one_run, args.cluster, on_ready=lambda line: print(line, file=sys.stderr))
    else:
        results = local_pool(todo, _one_run, args.jobs or os.cpu_count() or 1)
    bar, failures = ProgressBar(len(todo)), []
    try:
        with contextlib.closing(results):
            for job, result in results:
                if is_failure(result):
                    failures.append(result)
                    log.add(job["key"], failure=_clean(result))
                    bar.update(False, failure_line(result))
                else:
                    log.add(job["key"], report=_clean(result))
                    bar.update(True, _run_line(result))
    except KeyboardInterrupt:
        return None
    finally:
        bar.close()
    return failures


def _check_args(args: argparse.Namespace, objects: Sequence[str], strategies: Sequence[str]) -> None:
    """Every value before the pool starts (one line per problem, exit 2): the counts, each
    strategy against the planner's rule, each object name or file."""
    from tactile_sim.objects import make_object

    from .param_checks import ParamsError, check_cli, param_spec

    errors = [f"--{k} {v}: must be ≥ 1" for k, v in (("seeds", args.seeds), ("jobs", args.jobs))
              if v is not None and v < 1]
    if args.cluster is not None:
        if args.jobs is not None:
            errors.append("--jobs with --cluster: the cluster's workers set how many runs go at once")
        try:
            cluster_address(args.cluster)
        except ValueError as exc:
            errors.append(str(exc))
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
