"""The 3D progress figure: three views of the estimate, the touches in order, the IoU curves.

Top row, three viewpoints of the world frame (metres): the estimated surface
(μ = 0, marching tetrahedra on the estimator's lattice) coloured by log10 σ
of the posterior at each triangle, lightly shaded; the true surface as a
ghost of horizontal contour rings (marching squares of the true SDF at
evenly spaced heights; the top view shows the lowest ring, the footprint);
each touch's followed path and approach coloured by its order, a slide's
trace, contacts with their normals, free-space probe ends. Bottom row: IoU
against travel and against robot time.

matplotlib's mplot3d (Agg, off-screen) draws it; it sorts polygons within
one collection only, so the layers are drawn in a fixed order (surface, rings,
paths, markers) and the view is the object's box: paths leaving it are clipped.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection  # noqa: E402

from .figure_curves import draw_iou_panel, title  # noqa: E402
from .figure_data import touch_geometry  # noqa: E402

SIGMA_CMAP = "viridis"
ORDER_CMAP = "autumn"
VIEWS = ((28.0, -60.0, "front left"), (28.0, 120.0, "back right"), (90.0, -90.0, "top"))
#: most triangles drawn per view (a coarser estimate is drawn past this: mplot3d is slow)
MAX_TRIANGLES = 12000


def truth_rings(obj, levels: int = 14, points: int = 90) -> list[np.ndarray]:
    """Horizontal contour segments (S, 2, 3) of the true surface at ``levels`` heights."""
    from tactile_gpis.levelset import marching_squares

    lo, hi = np.asarray(obj.bounds, dtype=float)
    lo, hi = lo - 0.005, hi + 0.005
    xs, ys = np.linspace(lo[0], hi[0], points), np.linspace(lo[1], hi[1], points)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    out = []
    for z in np.linspace(max(lo[2], 0.0) + 0.002, hi[2] - 0.006, levels):
        d = obj.sdf(np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])).reshape(X.shape)
        ls = marching_squares(d, [xs, ys])
        if len(ls.elements):
            seg = ls.vertices[ls.elements]
            out.append(np.concatenate([seg, np.full(seg.shape[:2] + (1,), z)], axis=2))
    return out


def estimate_mesh(estimator) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (T, 3, 3) of the estimated surface above the table and log10 σ at each."""
    from scipy.interpolate import RegularGridInterpolator

    ls = estimator.level_set()
    if len(ls.elements) == 0:
        return np.zeros((0, 3, 3)), np.zeros(0)
    tri = ls.vertices[ls.elements]
    tri = tri[tri[:, :, 2].max(axis=1) >= 0.0]
    sd = np.sqrt(np.maximum(estimator.lattice_variance(), 1e-30))
    interp = RegularGridInterpolator(estimator.lattice_axes, np.log10(sd), bounds_error=False, fill_value=None)
    return tri, interp(tri.mean(axis=1))


def _shade(rgba: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Lambert shading from a light above and in front (keeps colours readable: 0.55–1)."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)
    light = np.array([-0.4, -0.5, 0.77])
    k = 0.55 + 0.45 * np.abs(n @ (light / np.linalg.norm(light)))
    out = rgba.copy()
    out[:, :3] *= k[:, None]
    return out


def plot_progress_3d(report: dict, path, estimator=None, obj=None, estimate_xyz=None, truth_xyz=None,
                     dpi: int = 100) -> dict:
    """Write the 3D progress figure to ``path`` (PNG); the IoU crossings drawn, per x key."""
    fig = plt.figure(figsize=(18, 9.8))
    gs = fig.add_gridspec(2, 4, height_ratios=[1.5, 0.8], width_ratios=[1, 1, 1, 0.04], hspace=0.12,
                          wspace=0.08)
    tri, log_sd = estimate_mesh(estimator) if estimator is not None else (np.zeros((0, 3, 3)), np.zeros(0))
    if len(tri) > MAX_TRIANGLES:  # an even subsample keeps the look and the colours
        keep = np.linspace(0, len(tri) - 1, MAX_TRIANGLES).astype(int)
        tri, log_sd = tri[keep], log_sd[keep]
    norm = plt.Normalize(*(np.percentile(log_sd, [1, 99]) if len(log_sd) else (0, 1)))
    cmap = plt.get_cmap(SIGMA_CMAP)
    colours = _shade(cmap(norm(log_sd)), tri) if len(tri) else None
    rings = truth_rings(obj) if obj is not None else []
    geo = touch_geometry(report)
    box = _box(tri, rings, geo, estimate_xyz, truth_xyz)
    for col, (elev, azim, name) in enumerate(VIEWS):
        ax = fig.add_subplot(gs[0, col], projection="3d", computed_zorder=False)
        if len(tri):
            # edges in the face colour: no light seams between the triangles (antialiasing)
            ax.add_collection3d(Poly3DCollection(tri, facecolors=colours, edgecolors=colours, linewidths=0.3),
                                autolim=False)
        elif estimate_xyz is not None and len(estimate_xyz):
            ax.scatter(*np.asarray(estimate_xyz).T, s=1, c="tab:blue")
        top = elev >= 89.0
        # looking down, every ring would show through the estimate: the footprint only
        for seg in (rings[:1] if top else rings):
            ax.add_collection3d(Line3DCollection(seg, colors="k", linewidths=1.0 if top else 0.7,
                                                 alpha=0.8 if top else 0.55), autolim=False)
        if not rings and truth_xyz is not None and len(truth_xyz):
            ax.scatter(*np.asarray(truth_xyz)[::5].T, s=0.5, c="0.4", alpha=0.4)
        _draw_touches(ax, geo)
        ax.set_xlim(box[0, 0], box[1, 0])
        ax.set_ylim(box[0, 1], box[1, 1])
        ax.set_zlim(box[0, 2], box[1, 2])
        ax.set_box_aspect(box[1] - box[0])
        ax.view_init(elev=elev, azim=azim)
        ax.set_title(f"{name} (elevation {elev:.0f}°, azimuth {azim:.0f}°)", fontsize=9)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
        ax.set_zlabel("z (m)", fontsize=8)
        ax.tick_params(labelsize=6)
        if top:  # looking down: z is the depth
            ax.set_zticks([])
            ax.set_zlabel("")
        if col == 0:
            ax.legend(handles=_legend(geo, bool(rings)), loc="upper left", fontsize=7, framealpha=0.9)
    cax = fig.add_subplot(gs[0, 3])
    cb = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax)
    cb.set_label("estimated surface: log$_{10}$ σ of the posterior f (σ in m)")
    inner = gs[1, :3].subgridspec(1, 2, wspace=0.18)
    crossings = {}
    for col, key in enumerate(("travel_m", "time_s")):
        crossings[key] = draw_iou_panel(fig.add_subplot(inner[0, col]), report, key)
    fig.suptitle(title(report), fontsize=12)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return crossings


def _box(tri, rings, geo, estimate_xyz, truth_xyz, margin_m: float = 0.02) -> np.ndarray:
    """Around the estimate, the truth and the observed points (not the whole paths)."""
    pts = [tri.reshape(-1, 3)] if len(tri) else []
    pts += [seg.reshape(-1, 3) for seg in rings]
    pts += [g.point_xyz[None, :] for g in geo]
    pts += [np.asarray(a)[:, :3] for a in (estimate_xyz, truth_xyz) if a is not None and len(a)]
    if not pts:
        return np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    P = np.vstack(pts)
    lo, hi = P.min(0) - margin_m, P.max(0) + margin_m
    lo[2] = max(lo[2], 0.0)
    return np.stack([lo, hi])


def _draw_touches(ax, geo) -> None:
    if not geo:
        return
    cmap = plt.get_cmap(ORDER_CMAP)
    n = len(geo)
    colour = [cmap(0.9 * i / max(n - 1, 1)) for i in range(n)]
    segs, seg_c = [], []
    for g, c in zip(geo, colour):
        if len(g.path_xyz):
            segs += list(np.stack([g.path_xyz[:-1], g.path_xyz[1:]], axis=1))
            seg_c += [c] * (len(g.path_xyz) - 1)
            segs.append(np.stack([g.path_xyz[-1], g.approach_end_xyz]))
            seg_c.append(c)
    slides = [(g, c) for g, c in zip(geo, colour) if len(g.slide_xyz)]
    for g, c in slides:  # from the first contact along the surface, each streamed contact a dot
        ax.plot(*g.slide_line_xyz.T, "-", color=c, lw=2.5, alpha=0.7, axlim_clip=True)
        ax.scatter(*g.slide_xyz.T, s=3, c="k", depthshade=False, axlim_clip=True)
    if segs:
        ax.add_collection3d(Line3DCollection(segs, colors=seg_c, linewidths=0.7, alpha=0.6), autolim=False,
                            axlim_clip=True)
    con = [(g, c) for g, c in zip(geo, colour) if g.contact]
    free = [(g, c) for g, c in zip(geo, colour) if not g.contact]
    if con:
        P = np.array([g.point_xyz for g, _ in con])
        ax.scatter(*P.T, s=18, c=[c for _, c in con], edgecolors="k", linewidths=0.5, depthshade=False,
                   axlim_clip=True)
        with_n = [(g.point_xyz, g.normal_xyz) for g, _ in con if g.normal_xyz is not None]
        if with_n:
            A = np.array([p for p, _ in with_n])
            N = np.array([v for _, v in with_n])
            N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
            ax.quiver(*A.T, *N.T, length=0.015, color="k", linewidths=0.8, arrow_length_ratio=0.3,
                      axlim_clip=True)
    if free:
        P = np.array([g.point_xyz for g, _ in free])
        ax.scatter(*P.T, s=30, c=[c for _, c in free], marker="X", edgecolors="k", linewidths=0.4,
                   depthshade=False, axlim_clip=True)


def _legend(geo, rings: bool) -> list:
    cmap = plt.get_cmap(ORDER_CMAP)
    h = [Line2D([], [], color="k", lw=0.8, alpha=0.6, label="true surface (height rings)")] if rings else []
    h.append(Line2D([], [], marker="s", ls="", ms=8, mfc=plt.get_cmap(SIGMA_CMAP)(0.6), mec="none",
                    label="estimate (μ = 0), colour = σ"))
    if geo:
        h += [Line2D([], [], color=cmap(0.0), lw=1, label=f"paths, touch 0 (red) → {len(geo) - 1} (yellow)"),
              Line2D([], [], marker="o", ls="", mfc=cmap(0.5), mec="k", label="contact (→ normal)"),
              Line2D([], [], marker="X", ls="", mfc=cmap(0.5), mec="k", label="free-space probe end")]
        if any(len(g.slide_xyz) for g in geo):
            h.append(Line2D([], [], color=cmap(0.5), lw=2.5, marker=".", mfc="k", mec="k", ms=4,
                            label="slide (• streamed contacts)"))
    return h
