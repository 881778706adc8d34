"""Long-run (soak) analysis: per-touch curves and whether they stay bounded or grow linearly.

ROS-free (numpy only). :mod:`tactile_bringup.soak` samples a graph run (resident
memory of each node, MCAP size, the explorer's touch count, over wall time) and
hands the samples here; this module turns them into one value per touch, fits
a line to each curve after a warm-up and judges it:

* ``bounded``: the fitted line rises by at most ``bound`` over the judged range
  (RSS of a node whose state does not grow with contacts; a line, not the peak,
  so that one slow decision or one allocator step does not decide);
* ``linear``: it grows, but a straight line explains it (the quadratic term adds
  less than ``curvature_tol`` of the growth over the range): the MCAP size, or
  a quantity proportional to the contacts held;
* ``superlinear``: it grows faster than a line (a leak or an O(n²) state that
  matters at this n).

Units are whatever the caller passes (the runner uses MB and ms); the slope is
in those units per touch.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Mapping, Optional, Sequence

import numpy as np

VERDICTS = ("bounded", "linear", "superlinear")


@dataclass(frozen=True)
class Growth:
    """How a per-touch curve grows after its warm-up (units of the curve per touch)."""

    slope: float          # least-squares slope after the warm-up, units / touch
    intercept: float      # of that line, units
    r2: float             # of that line (1 for a perfect line; NaN for a constant curve)
    growth: float         # rise of the fitted line over the judged range, slope·(last − first), units
    peak_rise: float      # max over the judged range − the value at its first touch, units
    curvature: float      # quadratic coefficient of a parabola fitted after the warm-up, units / touch²
    first: int            # first touch of the fit (the warm-up's end)
    last: int             # last touch of the fit
    verdict: str          # one of VERDICTS

    def as_dict(self) -> dict:
        return asdict(self)


def per_touch(sample_touches: Sequence[int], values: Sequence[float], n_touches: int) -> np.ndarray:
    """One value per touch 1..``n_touches``: the maximum of the samples taken while
    ``k`` touches were done (from the end of touch ``k`` to the end of touch ``k + 1``).

    A touch during which no sample was taken gets the previous touch's value (NaN
    before the first sampled touch). Samples with ``touches == 0`` (start-up) or
    beyond ``n_touches`` are not used; NaN samples (a process not found) are skipped.

    Returns:
        float array of shape (n_touches,).
    """
    k = np.asarray(sample_touches, dtype=int)
    v = np.asarray(values, dtype=float)
    if k.shape != v.shape or k.ndim != 1:
        raise ValueError(f"touch counts and values must be 1-D of one length, got {k.shape} and {v.shape}")
    if n_touches < 1:
        raise ValueError(f"n_touches must be >= 1, got {n_touches}")
    keep = (k >= 1) & (k <= n_touches) & np.isfinite(v)
    out = np.full(n_touches, -np.inf)
    np.maximum.at(out, k[keep] - 1, v[keep])
    out[np.isneginf(out)] = np.nan
    # carry the last sampled value forward over touches without a sample
    idx = np.where(np.isfinite(out), np.arange(n_touches), -1)
    np.maximum.accumulate(idx, out=idx)
    filled = np.where(idx >= 0, out[np.maximum(idx, 0)], np.nan)
    return filled


def fit_line(x: Sequence[float], y: Sequence[float]) -> tuple[float, float, float]:
    """Least-squares line ``y ≈ slope·x + intercept``; returns (slope, intercept, r²).

    r² is NaN when ``y`` is constant (nothing to explain).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size < 2:
        raise ValueError(f"a line needs at least 2 points, got {x.size}")
    slope, intercept = np.polyfit(x, y, 1)
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    ss_res = float(np.sum((y - (slope * x + intercept)) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")
    return float(slope), float(intercept), r2


def judge_growth(values: Sequence[float], *, warmup: int, bound: float,
                 curvature_tol: float = 0.25, last: Optional[int] = None) -> Growth:
    """Judge the per-touch curve ``values`` (touch 1 first) from touch ``warmup`` to ``last``.

    Args:
        values: one value per touch (NaN entries are left out of the fits).
        warmup: first touch (1-based) judged; before it, start-up allocations.
        bound: largest rise of the fitted line still called ``bounded`` (units of values).
        last: last touch judged (default: the last one).
        curvature_tol: a growing curve is ``linear`` when the parabola's quadratic term
            over the judged range, ``|c2|·(last − first)²``, is at most this fraction of
            the line's rise ``|slope|·(last − first)``, else ``superlinear``.
    """
    y_all = np.asarray(values, dtype=float)
    if bound < 0 or not np.isfinite(bound):
        raise ValueError(f"bound must be a finite number >= 0, got {bound}")
    if warmup < 1:
        raise ValueError(f"warmup must be >= 1 (touches count from 1), got {warmup}")
    x_all = np.arange(1, y_all.size + 1, dtype=float)
    sel = (x_all >= warmup) & (x_all <= (last if last is not None else y_all.size)) & np.isfinite(y_all)
    x, y = x_all[sel], y_all[sel]
    if x.size < 3:
        raise ValueError(f"need at least 3 sampled touches from touch {warmup} on, got {x.size}")
    slope, intercept, r2 = fit_line(x, y)
    span = float(x[-1] - x[0])
    growth = slope * span
    peak_rise = float(np.max(y) - y[0])
    curvature = float(np.polyfit(x - x[0], y, 2)[0])
    if growth <= bound:
        verdict = "bounded"
    elif abs(curvature) * span ** 2 <= curvature_tol * abs(slope) * span or curvature < 0:
        verdict = "linear"  # a concave curve (growth slowing down) is not superlinear either
    else:
        verdict = "superlinear"
    return Growth(slope, float(intercept), r2, growth, peak_rise, curvature, int(x[0]), int(x[-1]), verdict)


def table_every(curves: Mapping[str, Sequence[float]], step: int = 10) -> list[dict]:
    """Rows of the curves at touches ``step``, ``2·step``, … and the last touch.

    Each row: ``{"touch": k, name: value at touch k, ...}``; curves whose name ends in
    ``_ms`` (per-decision times) give the mean over the touches since the previous row
    instead (one decision is noisy).
    """
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    n = max((len(v) for v in curves.values()), default=0)
    marks = list(range(step, n + 1, step))
    if n and (not marks or marks[-1] != n):
        marks.append(n)
    rows, prev = [], 0
    for k in marks:
        row: dict = {"touch": k}
        for name, v in curves.items():
            arr = np.asarray(v, dtype=float)
            if name.endswith("_ms"):
                seg = arr[prev:k]
                seg = seg[np.isfinite(seg)]
                row[name] = float(seg.mean()) if seg.size else float("nan")
            else:
                row[name] = float(arr[k - 1]) if k <= arr.size else float("nan")
        rows.append(row)
        prev = k
    return rows


def format_table(rows: list[dict], digits: int = 1) -> str:
    """The rows of :func:`table_every` as an aligned text table (one line per row)."""
    if not rows:
        return "(no touches)"
    names = list(rows[0].keys())
    width = {n: max(len(n), 7) for n in names}
    head = "  ".join(n.rjust(width[n]) for n in names)
    lines = [head]
    for r in rows:
        cells = []
        for n in names:
            v = r[n]
            cells.append((str(v) if n == "touch" else ("—" if not np.isfinite(v) else f"{v:.{digits}f}"))
                         .rjust(width[n]))
        lines.append("  ".join(cells))
    return "\n".join(lines)
