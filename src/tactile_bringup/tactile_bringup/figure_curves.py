"""The IoU panels of the progress figures: IoU against travel or robot time, levels marked."""

from __future__ import annotations

import numpy as np

from .figure_data import IOU_KEYS, LEVELS, crossing, iou_keys, step_curve

X_LABELS = {"travel_m": "fingertip travel (m)", "time_s": "robot time (s)"}
STYLES = {"iou": dict(color="tab:blue", lw=1.8, ls="-"),
          "iou_reachable": dict(color="tab:green", lw=1.5, ls="--")}
LEVEL_COLOURS = {0.90: "tab:orange", 0.95: "tab:red"}


def draw_iou_panel(ax, report: dict, x_key: str) -> dict:
    """Step curves of every IoU the touches carry against ``x_key``, with the 0.90/0.95
    lines and a marker where each curve first reached them.

    Returns:
        {(curve key, level): (x, IoU)} of the crossings drawn.
    """
    keys = iou_keys(report)
    for level in LEVELS:
        ax.axhline(level, color=LEVEL_COLOURS[level], lw=0.8, ls=":", zorder=1)
        ax.text(0.0, level, f" {level:.2f}", color=LEVEL_COLOURS[level], fontsize=7, va="bottom",
                ha="left", transform=ax.get_yaxis_transform())
    notes, drawn = [], {}
    for key in keys:
        x, y = step_curve(report, x_key, key)
        ax.step(x, y, where="post", label=IOU_KEYS[key], zorder=3, **STYLES[key])
        ax.plot(x[-len(report["touches"]):], y[-len(report["touches"]):], "o", ms=2.5,
                color=STYLES[key]["color"], zorder=3)
        for level in LEVELS:
            hit = crossing(x, y, level)
            if hit is None:
                continue
            ax.axvline(hit[0], color=LEVEL_COLOURS[level], lw=0.7, ls=(0, (2, 2)), ymax=hit[1] / 1.02)
            drawn[(key, level)] = hit
            ax.plot(*hit, marker="D", ms=6, mfc="none", mec=LEVEL_COLOURS[level], mew=1.4, zorder=4)
            value = f"{hit[0]:.2f} m" if x_key == "travel_m" else f"{hit[0]:.0f} s"
            touch = int(np.argmax(y >= level)) - (len(y) - len(report["touches"]))
            notes.append(f"{IOU_KEYS[key]} ≥ {level:.2f} at {value} (touch {touch})")
    if not keys:
        ax.text(0.5, 0.5, "no IoU recorded (no ground truth)", ha="center", va="center",
                transform=ax.transAxes, fontsize=9, color="0.4")
    reached = "\n".join(notes) if notes else "0.90 not reached"
    ax.text(0.98, 0.04, reached, ha="right", va="bottom", fontsize=7, transform=ax.transAxes,
            bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="0.8", alpha=0.9))
    ax.set_xlabel(X_LABELS[x_key])
    ax.set_ylabel("IoU")
    ax.set_ylim(0, 1.02)
    ax.set_xlim(left=0)
    ax.grid(alpha=0.3)
    if keys:
        ax.legend(loc="center right", fontsize=7)
    return drawn


def title(report: dict) -> str:
    """One line: object, mode, strategy, seed and the run's totals."""
    s = report["summary"]
    iou = "n/a" if s.get("final_iou") is None else f"{s['final_iou']:.3f}"
    return (f"{report['object']} ({report['mode']}), {report['strategy']}, seed {report['seed']}: "
            f"{s['touches']} touches, final IoU {iou}, travel {s['travel_m']:.2f} m, "
            f"robot time {s['time_s']:.0f} s ({s.get('stopped_because', '')})")
