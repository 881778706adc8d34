"""Figures of exploration runs (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from .figure_data import IOU_KEYS, LEVELS, band, group_key, iou_keys  # noqa: E402,F401 (re-exported)


def plot_progress(report: dict, path: Path, estimate_xy: Optional[np.ndarray] = None,
                  truth_xy: Optional[np.ndarray] = None, *, estimator=None, obj=None) -> Path:
    """The run's progress figure (PNG): what the run saw and did, and its IoU curves.

    2D (:mod:`tactile_bringup.figures2d`): the posterior σ field, estimate over truth,
    their disagreement, every path, approach, contact (with normal) and probe in order;
    3D (:mod:`tactile_bringup.figures3d`): three views of the estimated surface coloured
    by σ over the true one. Beside them IoU (and ``iou_reachable`` when the touches carry
    it) against travel and robot time, with where 0.90/0.95 were reached.

    Args:
        estimator: the run's ``ShapeEstimator`` (σ field, estimated contour/surface);
            without it the estimate is drawn from the points ``estimate_xy``.
        obj: the true object (``tactile_sim`` SDF object); without it the truth is
            drawn from the points ``truth_xy`` (or not at all).
    """
    if report.get("mode") not in ("2d", "3d"):
        raise ValueError(f"report mode must be '2d' or '3d', got {report.get('mode')!r}")
    path = Path(path)
    if report["mode"] == "2d":
        from .figures2d import plot_progress_2d

        plot_progress_2d(report, path, estimator, obj, estimate_xy, truth_xy)
    else:
        from .figures3d import plot_progress_3d

        plot_progress_3d(report, path, estimator, obj, estimate_xy, truth_xy)
    return path


def plot_strategies(runs: Sequence[dict], path: Path, key: str = "travel_m", y_key: str = "iou",
                    group: Callable[[dict], str] = group_key) -> Path:
    """IoU against travel (or time) per strategy: the median over runs and the inter-quartile band.

    One panel per ``group(run)`` (default: the run's ``family`` field, else its
    object), and a first panel over every run when there are several. A run keeps
    its final IoU after it ended (as the benchmark's budget table counts it).
    ``y_key``: ``iou`` or ``iou_reachable`` (every touch must carry it).
    """
    if not runs:
        raise ValueError("plot_strategies needs at least one run")
    if y_key not in IOU_KEYS:
        raise ValueError(f"y_key must be one of {sorted(IOU_KEYS)}, got '{y_key}'")
    groups = sorted({group(r) for r in runs})
    panels = ([("all runs", list(runs))] if len(groups) > 1 else []) + \
        [(g, [r for r in runs if group(r) == g]) for g in groups]
    strategies = sorted({r["strategy"] for r in runs})
    colours = {s: f"C{i}" for i, s in enumerate(strategies)}
    cols = min(4, len(panels))
    rows = int(np.ceil(len(panels) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 3.4 * rows), squeeze=False)
    for ax, (name, sel) in zip(axes.ravel(), panels):
        x_max = max(float(r["touches"][-1][key]) if r["touches"] else 0.0 for r in sel)
        for strat in strategies:
            mine = [r for r in sel if r["strategy"] == strat]
            if not mine:
                continue
            b = band(mine, key, y_key, x_max=x_max)
            ax.fill_between(b.grid, b.q25, b.q75, color=colours[strat], alpha=0.18, lw=0, step="post")
            ax.step(b.grid, b.median, where="post", color=colours[strat], lw=1.6,
                    label=f"{strat} ({b.runs})")
        for level in LEVELS:
            ax.axhline(level, color="grey", lw=0.6, ls="--")
        ax.set_title(name, fontsize=9, fontweight="bold" if name == "all runs" else "normal")
        ax.set_ylim(0, 1.02)
        ax.set_xlim(0, x_max)
        ax.grid(alpha=0.3)
        ax.set_xlabel("fingertip travel (m)" if key == "travel_m" else "robot time (s)", fontsize=8)
        ax.set_ylabel(IOU_KEYS[y_key], fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7, loc="lower right", title="median, 25–75 % (runs)", title_fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_gallery(shapes: Sequence[tuple[str, np.ndarray, np.ndarray]], path: Path,
                 cols: Optional[int] = None) -> Path:
    """Final estimated shapes (orange) over the true ones (black), top view in 3D:
    (title, estimate_xy, truth_xy) per panel, ``cols`` per row (default up to 5; the
    benchmark passes its number of strategies: one object per row). Each panel shows
    the truth's box plus 30 % on each side (an estimate beyond it is cut)."""
    if not shapes:
        raise ValueError("plot_gallery needs at least one shape")
    cols = int(cols) if cols else min(5, len(shapes))
    if cols < 1:
        raise ValueError(f"cols must be at least 1, got {cols}")
    rows = int(np.ceil(len(shapes) / cols))
    size = 3.0 if rows <= 6 else 2.2
    fig, axes = plt.subplots(rows, cols, figsize=(size * cols, size * rows), squeeze=False)
    for ax, (title, est, truth) in zip(axes.ravel(), shapes):
        est, truth = np.asarray(est, dtype=float), np.asarray(truth, dtype=float)
        if len(truth):
            ax.plot(truth[:, 0], truth[:, 1], ".", ms=1.2, color="k")
            lo, hi = truth[:, :2].min(0), truth[:, :2].max(0)
            centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo).max() * 1.3
            ax.set_xlim(centre[0] - half, centre[0] + half)
            ax.set_ylim(centre[1] - half, centre[1] + half)
        if len(est):
            ax.plot(est[:, 0], est[:, 1], ".", ms=0.9, color="tab:orange")
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes.ravel()[len(shapes):]:
        ax.axis("off")
    fig.legend(handles=[Line2D([], [], marker="o", ls="", color="k", label="true"),
                        Line2D([], [], marker="o", ls="", color="tab:orange", label="estimate")],
               loc="lower right", fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
