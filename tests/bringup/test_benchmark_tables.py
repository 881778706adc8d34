"""tactile-benchmark's reachable-IoU tables against hand computations on synthetic runs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_bringup import benchmark
from tactile_bringup.report import summarise


def run(obj: str, strategy: str, seed: int, reach: list[float], travel: list[float]) -> dict:
    """A report with touches at the given cumulative travel (time = 10 s per metre)."""
    touches = [{"iou": v, "iou_reachable": v, "travel_m": t, "time_s": 10 * t, "decision_ms": 20.0}
               for v, t in zip(reach, travel)]
    return {"object": obj, "strategy": strategy, "seed": seed, "mode": "2d", "touches": touches,
            "summary": summarise(touches, 0.1, "touch budget"), "wall_s": 1.0}


def test_ratios_are_geometric_means_of_per_object_medians():
    runs = []
    # Object A: proposed reaches 0.95 at 1 m (all seeds), uncertainty at 2 m -> ratio 0.5.
    # Object B: proposed at 3 m, uncertainty at 1.5 m -> ratio 2.  Geometric mean: 1.
    for seed in range(3):
        runs.append(run("gen2d-000-blob", "proposed", seed, [0.5, 0.96], [0.5, 1.0]))
        runs.append(run("gen2d-000-blob", "uncertainty", seed, [0.5, 0.96], [1.0, 2.0]))
        runs.append(run("gen2d-001-spiky", "proposed", seed, [0.5, 0.97], [1.0, 3.0]))
        runs.append(run("gen2d-001-spiky", "uncertainty", seed, [0.5, 0.97], [1.0, 1.5]))
    table = benchmark.ratio_table(runs, baselines=("uncertainty",))
    row = next(line for line in table.splitlines() if line.startswith("| uncertainty"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[2] == "1.00" and cells[4] == "1.00"  # travel and time to 0.95
    assert cells[5] == "2 (2 / 2)" and cells[6] == "1.00"
    # Only object A: 0.5.
    only_a = benchmark.ratio_table([r for r in runs if r["object"] == "gen2d-000-blob"], baselines=("uncertainty",))
    assert "| uncertainty | 0.50 | 0.50 | 0.50 | 0.50 |" in only_a


def test_a_run_that_never_reaches_counts_with_its_whole_travel():
    runs = [run("gen2d-002-convex", "proposed", s, [0.5, 0.8], [1.0, 4.0]) for s in range(3)]
    runs += [run("gen2d-002-convex", "uncertainty", s, [0.5, 0.96], [1.0, 2.0]) for s in range(3)]
    per = benchmark._per_object(runs)
    row = per[("gen2d-002-convex", "proposed")]
    assert row[("travel", "0.95")] == 4.0 and not row[("travel", "0.95", "median_reached")]
    obj_table = benchmark.reachable_object_table(runs)
    assert "| gen2d-002-convex | convex | proposed | 3 | 0.800 | ≥4.00 | ≥4.00 | ≥40 | ≥40 | 0/3 |" in obj_table
    assert "| uncertainty | 2.00 | 2.00 |" in benchmark.ratio_table(runs, baselines=("uncertainty",))
    below = benchmark.below_target(runs)
    assert "**proposed** (1 of 1): gen2d-002-convex (0.800)" in below
    assert "**uncertainty** (0 of 1): none" in below


def test_family_table_and_names():
    assert benchmark.family_of("gen2d-017-letter_H") == "letter_H"
    assert benchmark.family_of("gen3d-s4-002-superquadric") == "superquadric"
    assert benchmark.family_of("circle") == "builtin"
    runs = [run("gen2d-000-blob", "proposed", 0, [0.95], [1.0]), run("gen2d-011-blob", "proposed", 0, [0.95], [3.0])]
    fam = benchmark.family_table(runs)
    assert "| blob | proposed | 2 | 2.00 | 2.00 | 20 | 20 | 2/2 | 0.950 |" in fam


def test_suite_objects():
    assert benchmark.suite_objects("2d") == ["circle", "ellipse", "rounded_square", "triangle", "star", "kidney",
                                             "l_shape", "c_shape"]
    names = benchmark.suite_objects("3d", "generated", 12, 3)
    assert names == benchmark.suite_objects("3d", "generated", 12, 3) and len(names) == 12
    assert names[0] == "gen3d-s3-000-prism"
    assert len(benchmark.suite_objects("2d", "generated")) == 33
    with pytest.raises(ValueError, match="--count 0"):
        benchmark.suite_objects("2d", "generated", 0)


def test_old_runs_without_the_reachable_iou_still_summarise(tmp_path):
    runs = [run("circle", "proposed", 0, [0.5, 0.96], [1.0, 2.0])]
    for r in runs:
        for t in r["touches"]:
            del t["iou_reachable"]
        r["summary"] = {k: v for k, v in r["summary"].items() if "reachable" not in k}
    path = tmp_path / "runs.json"
    path.write_text(json.dumps(runs))
    assert benchmark.main(["--from-runs", str(path), "--out", str(tmp_path / "out")]) == 0
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "carry no reachable IoU" in md and "| circle | proposed | 1 |" in md
    assert np.isfinite(benchmark._geomean([1.0, 2.0]))


def test_ratios_are_taken_for_the_modes_default_strategy_when_it_was_run():
    from tactile_bringup.benchmark import DEFAULT_STRATEGY, default_strategy

    two = [{"mode": "2d", "strategy": s} for s in ("info_travel", "proposed", "sequential")]
    assert default_strategy(two) == "info_travel"  # explore_2d / soc_planner.yaml
    assert default_strategy([{"mode": "3d", "strategy": s} for s in ("proposed", "info_travel")]) == "info_travel"
    assert default_strategy([{"mode": "2d", "strategy": "proposed"}]) == DEFAULT_STRATEGY  # not run: the fallback


def test_a_run_that_ends_below_its_best_is_counted_with_the_worst_named():
    runs = [run("gen3d-002-superquadric", "proposed", 0, [0.5, 0.98, 0.965], [1.0, 2.0, 3.0]),  # drop 0.015
            run("gen3d-002-superquadric", "proposed", 1, [0.5, 0.90, 0.895], [1.0, 2.0, 3.0]),  # drop 0.005
            run("gen3d-004-compound", "proposed", 0, [0.7, 0.8, 0.75], [1.0, 2.0, 3.0]),  # drop 0.05
            run("gen3d-004-compound", "uncertainty", 0, [0.7, 0.8, 0.81], [1.0, 2.0, 3.0])]
    s = runs[0]["summary"]
    assert s["best_iou_reachable"] == 0.98 and abs(s["drop_from_best_reachable"] - 0.015) < 1e-12
    table = benchmark.drop_table(runs)
    assert "| proposed | 3 | 2 | gen3d-004-compound, 0 (0.800 → 0.750) |" in table
    assert "| uncertainty | 1 | 0 | — |" in table
    assert "Runs that end worse than they were" in benchmark.reachable_sections(runs)


def test_a_sweep_log_summarises_like_its_runs_json(tmp_path):
    from tactile_bringup.sweep_log import SweepLog

    runs = [run("circle", "proposed", s, [0.5, 0.96], [1.0, 2.0]) for s in range(2)]
    log = SweepLog(tmp_path / "runs.jsonl")
    for i, r in enumerate(runs):
        log.add(f"k{i}", report=dict(r, _shape=[[[0, 0]], [[0, 0]]]))
    (tmp_path / "runs.json").write_text(json.dumps(runs))
    assert benchmark.main(["--from-runs", str(tmp_path / "runs.jsonl"), "--out", str(tmp_path / "a")]) == 0
    assert benchmark.main(["--from-runs", str(tmp_path / "runs.json"), "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "a" / "summary.md").read_text() == (tmp_path / "b" / "summary.md").read_text()
