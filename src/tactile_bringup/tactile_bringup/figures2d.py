"""The 2D progress figure: the posterior over the plane, the touches in order, the IoU curves.

Left, in the x-y plane of the contour (world frame, metres): log10 σ of the
posterior f on the estimator's lattice as a colour field; the true contour
(solid black) and the estimated one (μ = 0, dashed); the cells where the
estimated and true solids disagree shaded (missed: inside the object but
not the estimate; extra: the converse); each touch's followed path and
approach coloured by its order, contacts with their normals, free-space
probe ends. Right: IoU against travel and against robot time.
"""

from __future__ import annotations

from typing import Optional

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from .figure_curves import draw_iou_panel, title  # noqa: E402
from .figure_data import touch_geometry  # noqa: E402

MISSED = "#d62728"
EXTRA = "#e6b800"
ESTIMATE = "#ff7f0e"
SIGMA_CMAP = "Greys"  # grey field: the coloured layers on top stay readable
ORDER_CMAP = "plasma"


def contour_length_m(obj, spacing_m: float = 0.0005) -> float:
    """Length of the true contour (marching squares of the SDF on a ``spacing_m`` grid over the
    object's box): one lap of the finger at contact."""
    from tactile_gpis.levelset import marching_squares

    lo, hi = np.asarray(obj.bounds, dtype=float)[:, :2] + [[-0.005], [0.005]]
    axes = [np.arange(lo[i], hi[i], spacing_m) for i in range(2)]
    X, Y = np.meshgrid(*axes, indexing="ij")
    ls = marching_squares(obj.sdf(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape), axes)
    seg = ls.vertices[ls.elements]
    return float(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1).sum())


def view_box(report: dict, bounds_xy: np.ndarray, truth_xy: Optional[np.ndarray],
             margin_m: float = 0.015) -> np.ndarray:
    """(2, 2) [lo; hi] box around the truth and every touch, inside the workspace ``bounds_xy``."""
    pts = [np.asarray(truth_xy)[:, :2]] if truth_xy is not None and len(truth_xy) else []
    for g in touch_geometry(report):
        pts.append(g.point_xyz[None, :2])
        if len(g.path_xyz):
            pts.append(g.path_xyz[:, :2])
    if not pts:
        return np.asarray(bounds_xy, dtype=float)
    P = np.vstack(pts)
    lo = np.maximum(P.min(0) - margin_m, bounds_xy[0])
    hi = np.minimum(P.max(0) + margin_m, bounds_xy[1])
    return np.stack([lo, hi])


def draw_plane(ax, report: dict, estimator=None, obj=None, estimate_xy=None, truth_xy=None, fig=None,
               grid_points: int = 300, cbar_ax=None) -> Optional[float]:
    """The left panel (see the module docstring); each layer is drawn when its data is given.
    Returns the true contour's length (m), None without the object."""
    bounds = np.asarray(estimator.bounds_m, dtype=float) if estimator is not None else None
    truth_pts = obj.surface_samples(0.001) if obj is not None else truth_xy
    if bounds is None:
        pts = [a[:, :2] for a in (truth_pts, estimate_xy) if a is not None and len(a)]
        pts += [g.point_xyz[None, :2] for g in touch_geometry(report)]
        P = np.vstack(pts) if pts else np.array([[0.0, 0.0], [1.0, 1.0]])
        bounds = np.stack([P.min(0) - 0.05, P.max(0) + 0.05])
    box = view_box(report, bounds, truth_pts)
    handles = []
    if estimator is not None:
        ax_x, ax_y = estimator.lattice_axes
        sd = np.sqrt(np.maximum(estimator.lattice_variance(), 1e-30))
        log_sd = np.log10(sd).T
        lo, hi = float(log_sd.min()), float(log_sd.max())
        # the darkest grey at 60 %: contours and paths stay visible over the most uncertain part
        mesh = ax.pcolormesh(ax_x, ax_y, log_sd, cmap=SIGMA_CMAP, shading="gouraud", zorder=0,
                             vmin=lo, vmax=hi + 0.6 * (hi - lo))
        if fig is not None:
            cb = fig.colorbar(mesh, cax=cbar_ax if cbar_ax is not None else ax.inset_axes([1.02, 0.0, 0.03, 1.0]))
            cb.ax.set_ylim(lo, hi)
            cb.set_label("log$_{10}$ σ of the posterior f (σ in m)")
    gx = np.linspace(box[0, 0], box[1, 0], grid_points)
    gy = np.linspace(box[0, 1], box[1, 1], grid_points)
    X, Y = np.meshgrid(gx, gy)
    G = np.column_stack([X.ravel(), Y.ravel()])
    true_in = est_in = lap_m = None
    if obj is not None:
        d = obj.sdf(G).reshape(X.shape)
        true_in = d < 0
        ax.contour(X, Y, d, levels=[0.0], colors="k", linewidths=2.0, zorder=3)
        lap_m = contour_length_m(obj)
    elif truth_xy is not None and len(truth_xy):
        ax.plot(truth_xy[:, 0], truth_xy[:, 1], ".", ms=1, color="k", zorder=3)
    handles.append(Line2D([], [], color="k", lw=2.0, label="true contour"))
    if estimator is not None:
        est_in = estimator.lattice_inside(G).reshape(X.shape)
        ax.contour(estimator.lattice_axes[0], estimator.lattice_axes[1], estimator.lattice_mean().T,
                   levels=[0.0], colors=ESTIMATE, linewidths=2.0, linestyles="--", zorder=4)
    elif estimate_xy is not None and len(estimate_xy):
        ax.plot(estimate_xy[:, 0], estimate_xy[:, 1], ".", ms=1.5, color=ESTIMATE, zorder=4)
    handles.append(Line2D([], [], color=ESTIMATE, lw=2.0, ls="--", label="estimate (μ = 0)"))
    if true_in is not None and est_in is not None:
        for mask, colour, label in ((true_in & ~est_in, MISSED, "missed (true, not estimated)"),
                                    (est_in & ~true_in, EXTRA, "extra (estimated, not true)")):
            if mask.any():
                ax.contourf(X, Y, mask.astype(float), levels=[0.5, 1.5], colors=[colour], alpha=0.45, zorder=2)
            handles.append(Patch(fc=colour, alpha=0.45, label=label))
    _draw_touches(ax, report, fig, handles)
    ax.set_xlim(box[0, 0], box[1, 0])
    ax.set_ylim(box[0, 1], box[1, 1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, world)")
    ax.set_ylabel("y (m, world)")
    # below the map: it never hides data
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.11), fontsize=8, ncol=4,
              frameon=False)
    return lap_m


def _draw_touches(ax, report: dict, fig, handles: list) -> None:
    geo = touch_geometry(report)
    if not geo:
        return
    # plasma without its palest yellow (unreadable on the light field)
    cmap = ListedColormap(plt.get_cmap(ORDER_CMAP)(np.linspace(0.0, 0.85, 256)))
    n = len(geo)
    colour = [cmap(i / max(n - 1, 1)) for i in range(n)]
    arrow_m = 0.012
    for g, c in zip(geo, colour):
        if len(g.path_xyz):
            ax.plot(g.path_xyz[:, 0], g.path_xyz[:, 1], "-", color=c, lw=1.0, alpha=0.85, zorder=5)
            end, hit = g.path_xyz[-1], g.approach_end_xyz
            ax.plot([end[0], hit[0]], [end[1], hit[1]], ":", color=c, lw=1.2, zorder=5)
    slides = [(g, c) for g, c in zip(geo, colour) if len(g.slide_xyz)]
    for g, c in slides:  # from the first contact along the surface, each streamed contact a dot
        S = g.slide_line_xyz
        ax.plot(S[:, 0], S[:, 1], "-", color=c, lw=2.2, alpha=0.6, solid_capstyle="round", zorder=6)
        ax.plot(g.slide_xyz[:, 0], g.slide_xyz[:, 1], ".", ms=2.5, color="k", zorder=6)
    if slides:
        handles.append(Line2D([], [], color="0.5", lw=2.2, alpha=0.6, marker=".", mfc="k", mec="k", ms=4,
                              label="slide (• streamed contacts)"))
    if len(geo[0].path_xyz):
        s = geo[0].path_xyz[0]
        ax.plot(s[0], s[1], "*", ms=11, mfc="white", mec="k", zorder=8)
        handles.append(Line2D([], [], marker="*", ls="", ms=10, mfc="white", mec="k", label="start"))
    con = [(g, c) for g, c in zip(geo, colour) if g.contact]
    free = [(g, c) for g, c in zip(geo, colour) if not g.contact]
    if con:
        P = np.array([g.point_xyz[:2] for g, _ in con])
        ax.scatter(P[:, 0], P[:, 1], s=28, c=[c for _, c in con], edgecolors="k", linewidths=0.6, zorder=7)
        with_n = [(g.point_xyz[:2], g.normal_xyz[:2]) for g, _ in con if g.normal_xyz is not None]
        if with_n:
            A = np.array([p for p, _ in with_n])
            N = np.array([nv for _, nv in with_n])
            N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
            ax.quiver(A[:, 0], A[:, 1], N[:, 0] * arrow_m, N[:, 1] * arrow_m, angles="xy", scale_units="xy",
                      scale=1.0, width=0.0035, color="k", zorder=6)
        handles.append(Line2D([], [], marker="o", ls="", mfc="0.6", mec="k", label="contact (→ normal)"))
    if free:
        P = np.array([g.point_xyz[:2] for g, _ in free])
        ax.scatter(P[:, 0], P[:, 1], s=40, c=[c for _, c in free], marker="X", edgecolors="k", linewidths=0.5,
                   zorder=7)
        handles.append(Line2D([], [], marker="X", ls="", mfc="0.6", mec="k", label="free-space probe end"))
    if any(len(g.path_xyz) for g in geo):
        handles.append(Line2D([], [], color=cmap(0.4), lw=1.0, label="path (—) and approach (⋯)"))
    for g in geo:  # order numbers, offset along the normal (outwards) when there is one
        off = g.normal_xyz[:2] if g.normal_xyz is not None else np.array([1.0, 1.0])
        off = off / max(np.linalg.norm(off), 1e-12) * (0.016 if g.contact else 0.008)
        ax.annotate(str(g.index), g.point_xyz[:2] + off, fontsize=7, ha="center", va="center", zorder=9,
                    color="0.1", bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))
    if fig is not None:
        sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, max(n - 1, 1)))
        cax = ax.inset_axes([0.56, 0.03, 0.41, 0.022])
        cb = fig.colorbar(sm, cax=cax, orientation="horizontal")
        cb.ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        cb.ax.tick_params(labelsize=7, top=True, labeltop=True, bottom=False, labelbottom=False)
        cb.ax.xaxis.set_label_position("top")
        cb.set_label("touch number (path colour)", fontsize=7)


def plot_progress_2d(report: dict, path, estimator=None, obj=None, estimate_xy=None, truth_xy=None,
                     dpi: int = 110) -> dict:
    """Write the 2D progress figure to ``path`` (PNG); the IoU crossings drawn, per x key."""
    fig = plt.figure(figsize=(15, 8))
    gs = fig.add_gridspec(2, 3, width_ratios=[1.45, 0.3, 1.0], hspace=0.3, wspace=0.05)
    ax_map = fig.add_subplot(gs[:, 0])
    lap_m = draw_plane(ax_map, report, estimator, obj, estimate_xy, truth_xy, fig)
    ax_map.set_title("posterior σ, estimate vs truth, touches in order", fontsize=10)
    crossings = {}
    for row, key in enumerate(("travel_m", "time_s")):
        ax = fig.add_subplot(gs[row, 2])
        crossings[key] = draw_iou_panel(ax, report, key)
        if key == "travel_m" and lap_m:  # travel in contour lengths (docs/architecture.md, Metrics)
            top = ax.secondary_xaxis("top", functions=(lambda x: x / lap_m, lambda n: n * lap_m))
            top.set_xlabel(f"laps of the true contour ({lap_m:.3f} m each)", fontsize=8)
            top.tick_params(labelsize=7)
    fig.suptitle(title(report), fontsize=11)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return crossings
