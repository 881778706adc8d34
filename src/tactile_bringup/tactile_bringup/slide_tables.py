"""Poke against slide: travel in contour lengths ("laps") and robot time, from benchmark runs.

``python -m tactile_bringup.slide_tables RUNS.json [RUNS.json ...] [--out FILE.md]`` reads the
``runs.json`` of one or more ``tactile-benchmark`` sweeps (2D; e.g. one with ``--touch poke`` and
one with ``--touch slide``) and prints Markdown tables:

- per object and (strategy, touch): median over seeds of the travel to IoU 0.90 / 0.95 in laps
  (travel / contour length of the true section, :func:`tactile_sim.contour.contour_length_m`), raw
  and reachable IoU, and the robot time to 0.90;
- the issue's criteria: the slide's median laps to 0.95 on convex and non-convex sections, and
  its robot time to 0.90 over the best poke strategy's (per object the fastest poke strategy by
  median time; geometric mean over objects).

A slide streams its contacts; its report carries checkpoints of the estimate along the slide
(``stream``), so the travel to a level is the first checkpoint or touch that reaches it (for a poke
the touch itself). A run that never reaches a level counts with its whole travel/time (a lower
bound, marked "≥" when the median run did not reach it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

LEVELS = (0.90, 0.95)


def label(run: dict) -> str:
    return f"{run['strategy']}/{run.get('touch', 'poke')}"


def checkpoints(run: dict) -> list[dict]:
    """Every point where the estimate was measured, in order: the stream of each touch, then the touch."""
    out = []
    for t in run["touches"]:
        out.extend(t.get("stream") or [])
        out.append(t)
    return out


def first_reaching(run: dict, level: float, key: str, iou_key: str = "iou") -> tuple[float, bool]:
    """(cumulative ``key`` at the first checkpoint with ``iou_key`` ≥ level, reached?); not reached:
    the run's total."""
    for c in checkpoints(run):
        if c.get(iou_key) is not None and c[iou_key] >= level:
            return float(c[key]), True
    return float(run["touches"][-1][key]) if run["touches"] else 0.0, False


def _contour_length(run: dict, cache: dict) -> float:
    if run.get("contour_length_m"):
        return float(run["contour_length_m"])
    name = run["object"]
    if name not in cache:
        from tactile_sim.contour import contour_length_m
        from tactile_sim.objects import make_object

        cache[name] = contour_length_m(make_object(name, mode="2d"))
    return cache[name]


def _convex(name: str, cache: dict) -> bool:
    if name not in cache:
        from tactile_sim.contour import is_convex
        from tactile_sim.objects import make_object

        cache[name] = is_convex(make_object(name, mode="2d"))
    return cache[name]


def per_object(runs: Sequence[dict]) -> dict:
    """{(object, label): medians over seeds}: laps and time to each level (raw and reachable)."""
    lengths: dict = {}
    out: dict = {}
    for key in sorted({(r["object"], label(r)) for r in runs}):
        sel = [r for r in runs if (r["object"], label(r)) == key]
        L = _contour_length(sel[0], lengths)
        row = {"seeds": len(sel), "L": L}
        for iou_key in ("iou", "iou_reachable"):
            for lv in LEVELS:
                tr = [first_reaching(r, lv, "travel_m", iou_key) for r in sel]
                tm = [first_reaching(r, lv, "time_s", iou_key) for r in sel]
                row[(iou_key, lv, "laps")] = float(np.median([v for v, _ in tr])) / L
                row[(iou_key, lv, "time")] = float(np.median([v for v, _ in tm]))
                row[(iou_key, lv, "ok")] = 2 * sum(ok for _, ok in tr) > len(sel)
        row["final"] = float(np.median([r["summary"]["final_iou"] for r in sel]))
        out[key] = row
    return out


def _c(row: dict, iou_key: str, lv: float, what: str, digits: int) -> str:
    v = row[(iou_key, lv, what)]
    return f"{'' if row[(iou_key, lv, 'ok')] else '≥'}{v:.{digits}f}"


def object_table(runs: Sequence[dict]) -> str:
    per = per_object(runs)
    conv: dict = {}
    lines = ["| object | convex | contour (m) | strategy/touch | seeds | laps to raw 0.90 | laps to raw 0.95 "
             "| laps to reach. 0.95 | time to raw 0.90 (s) | time to raw 0.95 (s) | final raw IoU |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for (obj, lab), row in per.items():
        lines.append(f"| {obj} | {'yes' if _convex(obj, conv) else 'no'} | {row['L']:.3f} | {lab} | {row['seeds']} "
                     f"| {_c(row, 'iou', 0.90, 'laps', 2)} | {_c(row, 'iou', 0.95, 'laps', 2)} "
                     f"| {_c(row, 'iou_reachable', 0.95, 'laps', 2)} | {_c(row, 'iou', 0.90, 'time', 0)} "
                     f"| {_c(row, 'iou', 0.95, 'time', 0)} | {row['final']:.3f} |")
    return "\n".join(lines) + "\n"


def _geomean(v: Sequence[float]) -> float:
    a = np.asarray([x for x in v if x > 0], dtype=float)
    return float(np.exp(np.mean(np.log(a)))) if len(a) else float("nan")


def criteria_table(runs: Sequence[dict]) -> str:
    """Each slide label against the issue's targets (medians over seeds, then over objects)."""
    per = per_object(runs)
    conv: dict = {}
    objects = sorted({o for o, _ in per})
    pokes = sorted({lab for _, lab in per if lab.endswith("/poke")})
    slides = sorted({lab for _, lab in per if lab.endswith("/slide")})
    lines = ["| strategy/touch | convex: median laps to raw 0.95 (target ≤ 1.5) | non-convex: median laps to raw "
             "0.95 (≤ 2.5) | non-convex: laps to reach. 0.95 | time to raw 0.90 over the best poke's (≤ 0.5, "
             "geo. mean) | objects |", "|---|---|---|---|---|---|"]
    for lab in slides + pokes:
        rows = {o: per[(o, lab)] for o in objects if (o, lab) in per}
        cx = [r[("iou", 0.95, "laps")] for o, r in rows.items() if _convex(o, conv)]
        nc = [r[("iou", 0.95, "laps")] for o, r in rows.items() if not _convex(o, conv)]
        ncr = [r[("iou_reachable", 0.95, "laps")] for o, r in rows.items() if not _convex(o, conv)]
        ratios = []
        for o, r in rows.items():
            best = [per[(o, p)][("iou", 0.90, "time")] for p in pokes if (o, p) in per]
            if best:
                ratios.append(r[("iou", 0.90, "time")] / min(best))
        med = lambda v: f"{np.median(v):.2f}" if v else "—"  # noqa: E731
        lines.append(f"| {lab} | {med(cx)} | {med(nc)} | {med(ncr)} | {_geomean(ratios):.2f} | {len(rows)} |")
    best_names = ", ".join(pokes) if pokes else "none"
    return ("\n".join(lines) + f"\n\nBest poke per object: the fastest (median time to raw 0.90) of {best_names}; "
            "a run that never reached a level counts with its whole travel/time.\n")


def tables(runs: Sequence[dict]) -> str:
    runs = [r for r in runs if r.get("mode", "2d") == "2d"]
    if not runs:
        raise ValueError("no 2D runs: laps are defined for 2D sections only")
    return (f"### Poke and slide against the issue's targets\n\n{criteria_table(runs)}\n"
            f"### Per object (medians over seeds; laps = travel / contour length)\n\n{object_table(runs)}")


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tactile_bringup.slide_tables", description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="runs.json of tactile-benchmark sweeps")
    parser.add_argument("--out", type=Path, default=None, help="also write the tables to this Markdown file")
    args = parser.parse_args(argv)
    runs = []
    for path in args.runs:
        if not path.is_file():
            print(f"error: {path}: no such file", file=sys.stderr)
            return 2
        runs += json.loads(path.read_text())
    try:
        md = tables(runs)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(md)
    if args.out:
        args.out.write_text(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
