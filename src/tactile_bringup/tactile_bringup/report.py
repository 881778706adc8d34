"""The exploration report: one schema for offline runs and graph runs.

::

    {"object", "mode", "strategy", "seed", "config": {...},
     "touches": [{"index", "target", "contact"|null, "normal"|null, "outcome",
                  "probe_end"|null (free space: the finger centre at max depth),
                  "travel_m" (cumulative), "time_s" (cumulative), "iou",
                  "iou_reachable", "surface_error_m", "decision_ms"}, ...],
     "summary": {"final_iou", "travel_to_iou_0.90_m", "travel_to_iou_0.95_m",
                 "time_to_iou_0.90_s", "time_to_iou_0.95_s", "auc_travel",
                 "final_iou_reachable", "travel_to_iou_reachable_0.90_m", ...,
                 "time_to_iou_reachable_0.95_s", "best_iou_reachable",
                 "drop_from_best_reachable" (best − final: more data made it worse),
                 "touches", "travel_m", "time_s", "stopped_because"}}

``iou`` is the raw IoU against the true solid; ``iou_reachable`` the IoU
against the finger-reachable solid (the true solid closed by a ball of the
tip radius; in 3D counted above the lowest tip-centre height:
:func:`tactile_sim.metrics.reachable_inside`). A report written before
``iou_reachable`` existed has None there.

``auc_travel`` is the area under the (1 − IoU) curve over cumulative travel
(metres), IoU held constant between touches (a step function starting at
the prior's IoU at zero travel): lower is better.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional, Sequence

TOUCH_KEYS = ("index", "target", "contact", "normal", "outcome", "travel_m", "time_s",
              "iou", "surface_error_m", "decision_ms")
SUMMARY_KEYS = ("final_iou", "travel_to_iou_0.90_m", "travel_to_iou_0.95_m",
                "time_to_iou_0.90_s", "time_to_iou_0.95_s", "auc_travel",
                "touches", "travel_m", "time_s", "stopped_because")
IOU_LEVELS = (0.90, 0.95)


def first_reaching(touches: Sequence[dict], level: float, key: str, iou_key: str = "iou") -> Optional[float]:
    """``touch[key]`` (cumulative travel or time) at the first touch whose ``touch[iou_key]`` ≥ level."""
    for t in touches:
        v = t.get(iou_key)
        if v is not None and v >= level:
            return float(t[key])
    return None


def auc_travel(touches: Sequence[dict], prior_iou: Optional[float]) -> Optional[float]:
    """∫ (1 − IoU) d(travel) over the run, IoU a step function of travel (None without IoU)."""
    if prior_iou is None or any(t["iou"] is None for t in touches):
        return None
    area, iou, travel = 0.0, prior_iou, 0.0
    for t in touches:
        area += (1.0 - iou) * (t["travel_m"] - travel)
        iou, travel = t["iou"], t["travel_m"]
    return float(area)


def summarise(touches: Sequence[dict], prior_iou: Optional[float], stopped_because: str,
              travel_m: Optional[float] = None, time_s: Optional[float] = None) -> dict:
    """The run's summary. ``travel_m``/``time_s``: the run's totals when it moved after its last
    recorded touch (aborted or lost touches before it stopped); default: the last touch's."""
    last_travel_m = touches[-1]["travel_m"] if touches else 0.0
    last_time_s = touches[-1]["time_s"] if touches else 0.0
    summary: dict[str, Any] = {
        "final_iou": touches[-1]["iou"] if touches else prior_iou,
        "auc_travel": auc_travel(touches, prior_iou),
        "touches": len(touches),
        "travel_m": max(last_travel_m, travel_m) if travel_m is not None else last_travel_m,
        "time_s": max(last_time_s, time_s) if time_s is not None else last_time_s,
        "stopped_because": stopped_because,
        "prior_iou": prior_iou,
    }
    for level in IOU_LEVELS:
        summary[f"travel_to_iou_{level:.2f}_m"] = first_reaching(touches, level, "travel_m")
        summary[f"time_to_iou_{level:.2f}_s"] = first_reaching(touches, level, "time_s")
    summary["final_iou_reachable"] = touches[-1].get("iou_reachable") if touches else None
    # More data should not make the estimate worse: the best reachable IoU seen in the run (after
    # any touch) and how far the final one lies below it.
    seen = [t.get("iou_reachable") for t in touches if t.get("iou_reachable") is not None]
    summary["best_iou_reachable"] = max(seen) if seen else None
    summary["drop_from_best_reachable"] = (max(seen) - seen[-1]) if seen else None
    # 3D: touches whose track put the finger's rod into the true object (a collision on a rig)
    shaft = [t.get("shaft_clearance_m") for t in touches if t.get("shaft_clearance_m") is not None]
    summary["shaft_collisions"] = sum(c < 0 for c in shaft) if shaft else None
    # 3D, tilted touches: the wrist behind the flange in the true object or the table
    wrist = [t.get("wrist_clearance_m") for t in touches if t.get("wrist_clearance_m") is not None]
    summary["wrist_collisions"] = sum(c < 0 for c in wrist) if wrist else None
    for level in IOU_LEVELS:
        summary[f"travel_to_iou_reachable_{level:.2f}_m"] = first_reaching(touches, level, "travel_m", "iou_reachable")
        summary[f"time_to_iou_reachable_{level:.2f}_s"] = first_reaching(touches, level, "time_s", "iou_reachable")
    return summary


def make_report(obj: str, mode: str, strategy: str, seed: int, config: dict,
                touches: list, prior_iou: float, stopped_because: str,
                travel_m: Optional[float] = None, time_s: Optional[float] = None) -> dict:
    """The report of a run (``travel_m``/``time_s``: its totals, see :func:`summarise`)."""
    return {
        "object": obj, "mode": mode, "strategy": strategy, "seed": seed, "config": config,
        "touches": touches, "summary": summarise(touches, prior_iou, stopped_because, travel_m, time_s),
    }


def check_report(report: dict) -> None:
    """Raise ValueError naming the first key that breaks the schema."""
    for key in ("object", "mode", "strategy", "seed", "config", "touches", "summary"):
        if key not in report:
            raise ValueError(f"report has no '{key}'")
    for i, t in enumerate(report["touches"]):
        missing = [k for k in TOUCH_KEYS if k not in t]
        if missing:
            raise ValueError(f"touch {i} lacks {missing}")
        if t["index"] != i:
            raise ValueError(f"touch {i} has index {t['index']}")
    missing = [k for k in SUMMARY_KEYS if k not in report["summary"]]
    if missing:
        raise ValueError(f"summary lacks {missing}")


def _clean(value: Any) -> Any:
    """JSON-safe: numpy scalars/arrays to Python, NaN/inf to None."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def write_report(report: dict, path: Path) -> None:
    """Write atomically (a partial report never replaces a complete one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(_clean(report), indent=1))
    tmp.replace(path)
