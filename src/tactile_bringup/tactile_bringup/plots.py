"""Figures of exploration runs (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _curve(report: dict, key: str) -> tuple[np.ndarray, np.ndarray]:
    """Step curve of IoU against cumulative ``key`` (travel_m or time_s), from zero."""
    xs = [0.0] + [t[key] for t in report["touches"]]
    ys = [report["summary"].get("prior_iou", 0.0)] + [t["iou"] for t in report["touches"]]
    return np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)


def plot_progress(report: dict, path: Path, estimate_xy: Optional[np.ndarray] = None,
                  truth_xy: Optional[np.ndarray] = None) -> Path:
    """IoU against travel and time; the touch sequence over the estimated and true shapes."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for ax, key, label in ((axes[0], "travel_m", "travel (m)"), (axes[1], "time_s", "robot time (s)")):
        x, y = _curve(report, key)
        ax.step(x, y, where="post", marker="o", ms=3)
        for level in (0.90, 0.95):
            ax.axhline(level, color="grey", lw=0.6, ls="--")
        ax.set_xlabel(label)
        ax.set_ylabel("IoU")
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
    ax = axes[2]
    if truth_xy is not None and len(truth_xy):
        ax.plot(truth_xy[:, 0], truth_xy[:, 1], ".", ms=1, color="0.6", label="true surface")
    if estimate_xy is not None and len(estimate_xy):
        ax.plot(estimate_xy[:, 0], estimate_xy[:, 1], ".", ms=1.5, color="tab:blue", label="estimate")
    touches = report["touches"]
    if touches:  # numbered in touch order (no lines: the finger's paths go around the object)
        for t in touches:
            p = t["contact"] if t["contact"] is not None else t["target"]
            ax.plot(p[0], p[1], "o" if t["contact"] is not None else "x",
                    color="tab:red" if t["contact"] is not None else "k", ms=4)
            ax.annotate(str(t["index"]), p[:2], fontsize=6, xytext=(3, 3), textcoords="offset points")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("touches in order (o contact, x free space)" + (" — top view" if report["mode"] == "3d" else ""))
    ax.legend(loc="upper right", fontsize=7)
    s = report["summary"]
    fig.suptitle(f"{report['object']} ({report['mode']}), {report['strategy']}, seed {report['seed']}: "
                 f"final IoU {s['final_iou']:.3f}, travel {s['travel_m']:.2f} m, time {s['time_s']:.0f} s")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_strategies(runs: Sequence[dict], path: Path, key: str = "travel_m") -> Path:
    """IoU against travel per object, strategies overlaid (median over seeds, thin lines per seed)."""
    objects = sorted({r["object"] for r in runs})
    strategies = sorted({r["strategy"] for r in runs})
    cols = min(4, len(objects))
    rows = int(np.ceil(len(objects) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.3 * rows), squeeze=False)
    colors = {s: f"C{i}" for i, s in enumerate(strategies)}
    for ax, obj in zip(axes.ravel(), objects):
        for strat in strategies:
            sel = [r for r in runs if r["object"] == obj and r["strategy"] == strat]
            for i, r in enumerate(sel):
                x, y = _curve(r, key)
                ax.step(x, y, where="post", color=colors[strat], lw=0.8, alpha=0.6,
                        label=strat if i == 0 else None)
        ax.set_title(obj, fontsize=9)
        ax.set_ylim(0, 1.02)
        ax.axhline(0.95, color="grey", lw=0.6, ls="--")
        ax.grid(alpha=0.3)
        ax.set_xlabel("travel (m)" if key == "travel_m" else "time (s)", fontsize=8)
    for ax in axes.ravel()[len(objects):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_gallery(shapes: Sequence[tuple[str, np.ndarray, np.ndarray]], path: Path) -> Path:
    """Final estimated shapes (blue) over the true ones (grey): (title, estimate_xy, truth_xy)."""
    cols = min(5, len(shapes))
    rows = int(np.ceil(len(shapes) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3 * cols, 3 * rows), squeeze=False)
    for ax, (title, est, truth) in zip(axes.ravel(), shapes):
        if len(truth):
            ax.plot(truth[:, 0], truth[:, 1], ".", ms=0.8, color="0.6")
        if len(est):
            ax.plot(est[:, 0], est[:, 1], ".", ms=0.8, color="tab:blue")
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes.ravel()[len(shapes):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
