"""What the figures draw, computed from report data (numpy only: no matplotlib, no ROS).

- IoU curves: a step function of cumulative travel (or robot time) that starts
  at the prior's IoU at zero and takes each touch's IoU from that touch on.
- Crossings: the first touch whose IoU reaches a level (0.90, 0.95), as the
  report's summary counts it.
- Bands over runs: each run's step curve sampled on a common grid (a run
  keeps its final IoU after it ended, as the budget table counts it), then
  the median and the 25th/75th percentiles at each grid point over the runs
  that have a value there (a curve without a recorded prior starts at its
  first touch).
- Touch geometry: the followed path, the approach segment, the observed
  point and a slide's contacts of each touch, in order (world frame, metres).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

#: IoU levels the figures mark (the report's summary levels).
LEVELS = (0.90, 0.95)
#: Curves a touch record may carry: key -> legend label.
IOU_KEYS = {"iou": "IoU", "iou_reachable": "reachable IoU"}


def iou_keys(report: dict) -> list[str]:
    """The IoU curves this report carries (``iou`` and, when recorded, ``iou_reachable``)."""
    touches = report["touches"]
    return [k for k in IOU_KEYS if touches and all(t.get(k) is not None for t in touches)]


def _prior(report: dict, key: str) -> Optional[float]:
    """The curve's value before the first touch (``summary.prior_<key>``), None if not recorded."""
    value = report.get("summary", {}).get("prior_" + key)
    return None if value is None else float(value)


def step_curve(report: dict, x_key: str = "travel_m", y_key: str = "iou") -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of the step curve: x[0] = 0 with the prior's value (when the summary has it:
    ``prior_iou``; else the curve starts at the first touch), then one point per touch."""
    if x_key not in ("travel_m", "time_s"):
        raise ValueError(f"x_key must be 'travel_m' or 'time_s', got '{x_key}'")
    touches = report["touches"]
    prior = _prior(report, y_key)
    x = [float(t[x_key]) for t in touches]
    y = [float(t[y_key]) for t in touches]
    if prior is not None or not touches:
        x, y = [0.0] + x, [prior or 0.0] + y
    return np.array(x), np.array(y)


def crossing(x: np.ndarray, y: np.ndarray, level: float) -> Optional[tuple[float, float]]:
    """(x, y) of the first point of a step curve with y ≥ level, None if never."""
    hit = np.nonzero(np.asarray(y) >= level)[0]
    if len(hit) == 0:
        return None
    return float(x[hit[0]]), float(y[hit[0]])


def sample_step(x: np.ndarray, y: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The step curve's value at each grid point: y of the last x ≤ grid (NaN before x[0])."""
    idx = np.searchsorted(np.asarray(x), np.asarray(grid), side="right") - 1
    out = np.asarray(y, dtype=float)[np.clip(idx, 0, len(y) - 1)]
    out[idx < 0] = np.nan
    return out


@dataclass(frozen=True)
class Band:
    """Median and inter-quartile range of several runs' curves on a common grid."""

    grid: np.ndarray
    median: np.ndarray
    q25: np.ndarray
    q75: np.ndarray
    runs: int


def band(reports: Sequence[dict], x_key: str = "travel_m", y_key: str = "iou", points: int = 200,
         x_max: Optional[float] = None) -> Band:
    """Median and quartiles over runs of the IoU step curves, on ``points`` grid points in [0, x_max]
    (default: the longest run)."""
    if not reports:
        raise ValueError("band needs at least one run")
    curves = [step_curve(r, x_key, y_key) for r in reports]
    top = max(float(c[0][-1]) for c in curves) if x_max is None else float(x_max)
    grid = np.linspace(0.0, max(top, 1e-9), int(points))
    Y = np.stack([sample_step(x, y, grid) for x, y in curves])
    q25, med, q75 = np.full((3, len(grid)), np.nan)
    some = ~np.all(np.isnan(Y), axis=0)  # before every run's first point (no prior): nothing
    q25[some], med[some], q75[some] = np.nanpercentile(Y[:, some], [25, 50, 75], axis=0)
    return Band(grid, med, q25, q75, len(reports))


@dataclass(frozen=True)
class TouchGeometry:
    """One touch as drawn: followed path (K, 3), approach end, observed point, normal."""

    index: int
    path_xyz: np.ndarray          # free-space path followed (may be empty when not recorded)
    point_xyz: np.ndarray         # contact point, or the probe end (finger centre at max depth)
    normal_xyz: Optional[np.ndarray]
    contact: bool
    slide_xyz: np.ndarray         # a slide's contacts in order, its first to its last = point (K, 3; empty: a poke)

    @property
    def approach_end_xyz(self) -> np.ndarray:
        """Where the approach from the path's end met the object (a slide: its first contact)."""
        return self.slide_xyz[0] if len(self.slide_xyz) else self.point_xyz

    @property
    def slide_line_xyz(self) -> np.ndarray:
        """The slide's trace (its contacts, ending at the recorded contact); empty for a poke."""
        if not len(self.slide_xyz):
            return self.slide_xyz
        return np.vstack([self.slide_xyz, self.point_xyz[None, :]])


def touch_geometry(report: dict) -> list[TouchGeometry]:
    """The touches of a report in order, with their paths when the records carry them."""
    out = []
    for t in report["touches"]:
        contact = t.get("contact") is not None
        point = t["contact"] if contact else (t.get("probe_end") or t.get("target"))
        path = t.get("path")
        slide = t.get("slide_contacts")
        out.append(TouchGeometry(
            index=int(t["index"]),
            path_xyz=np.asarray(path, dtype=float).reshape(-1, 3) if path else np.zeros((0, 3)),
            point_xyz=np.asarray(point, dtype=float),
            normal_xyz=np.asarray(t["normal"], dtype=float) if contact and t.get("normal") else None,
            contact=contact,
            slide_xyz=np.asarray(slide, dtype=float).reshape(-1, 3) if slide else np.zeros((0, 3)),
        ))
    return out


def group_key(run: dict) -> str:
    """The panel a run belongs to in the benchmark figures: its family when it carries one."""
    return str(run.get("family") or run["object"])
