"""Shape-estimation metrics against a known object (world frame, metres). ROS-free.

- IoU: |A ∩ B| / |A ∪ B| of the estimated and true solids, counted on a fixed
  evaluation lattice of cell centres (area in 2D, volume above the table in 3D).
- Surface error: mean distance from samples of the TRUE surface to the nearest
  point of the estimated zero level set (given as points); also the reverse
  direction (|sdf| of the estimated points, exact), their symmetric mean and
  the Hausdorff distance.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree

from tactile_sim.objects import SDFObject

InsideTest = Callable[[np.ndarray], np.ndarray]

#: True-surface samples closer than this to the table top and facing down are
#: the face the object stands on: not measurable, excluded in 3D.
TABLE_TOL_M = 1e-6


def evaluation_lattice(bounds: np.ndarray, resolution_m: float) -> np.ndarray:
    """Cell centres of a regular lattice over the box ``bounds`` (2, dim), C order.

    Each axis [lo, hi] is split into n = ceil((hi − lo)/resolution_m) equal
    cells. In 3D only z ≥ 0 is kept (the box is clipped at the table top).
    Returns (M, dim) points.
    """
    b = np.asarray(bounds, dtype=float)
    if b.ndim != 2 or b.shape[0] != 2 or b.shape[1] not in (2, 3) or not np.all(np.isfinite(b)):
        raise ValueError(f"bounds must be a finite (2, 2) or (2, 3) array [lo; hi], got shape {b.shape}")
    if not (np.isfinite(resolution_m) and resolution_m > 0.0):
        raise ValueError(f"resolution_m must be positive, got {resolution_m!r}")
    lo, hi = b[0].copy(), b[1].copy()
    if b.shape[1] == 3:
        lo[2] = max(lo[2], 0.0)
    if np.any(hi <= lo):
        raise ValueError(f"empty lattice box: lo={lo.tolist()} hi={hi.tolist()} (3D boxes are clipped at z = 0)")
    n = np.ceil((hi - lo) / resolution_m - 1e-9).astype(int)
    axes = [a + (np.arange(k) + 0.5) * (c - a) / k for a, c, k in zip(lo, hi, n)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))


def iou(inside_est: InsideTest, obj: SDFObject, lattice_points: np.ndarray) -> float:
    """Intersection over union of the estimate and the true object on lattice points.

    ``inside_est`` maps the (M, k) lattice points to a boolean (M,) array;
    the object is evaluated on their first ``obj.dim`` columns. Both empty → 1.
    """
    pts = np.asarray(lattice_points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] < obj.dim:
        raise ValueError(f"lattice_points must be (M, >= {obj.dim}), got shape {pts.shape}")
    est = np.asarray(inside_est(pts))
    if est.shape != (len(pts),):
        raise ValueError(f"inside_est returned shape {est.shape}, expected ({len(pts)},)")
    est = est.astype(bool)
    true = true_inside(obj, pts)
    union = np.count_nonzero(est | true)
    return 1.0 if union == 0 else np.count_nonzero(est & true) / union


def true_inside(obj: SDFObject, lattice_points: np.ndarray) -> np.ndarray:
    """obj.sdf(points) < 0, cached on the object per lattice (keyed by a hash of the points)."""
    pts = np.ascontiguousarray(lattice_points, dtype=float)
    key = (pts.shape, hashlib.blake2b(pts.tobytes(), digest_size=16).hexdigest())
    cache = obj.__dict__.setdefault("_inside_cache", {})
    if key not in cache:
        if len(cache) >= 4:
            cache.pop(next(iter(cache)))
        p = pts[:, :obj.dim]
        # Only points inside the object's bounding box can be inside (saves most SDF calls).
        box = np.all((p >= obj.bounds[0]) & (p <= obj.bounds[1]), axis=1)
        inside = np.zeros(len(p), dtype=bool)
        inside[box] = obj.sdf(p[box]) < 0.0
        cache[key] = inside
    return cache[key]


@dataclass(frozen=True)
class SurfaceError:
    """Distances between the true surface and an estimated level set [m]."""

    mean_m: float             #: mean over true-surface samples of the distance to the nearest estimated point
    max_m: float              #: max of the same (directed Hausdorff, true → estimate)
    est_to_true_mean_m: float  #: mean |sdf| of the estimated points (exact distance to the true surface)
    est_to_true_max_m: float
    symmetric_mean_m: float   #: average of the two directed means
    hausdorff_m: float        #: max of the two directed maxima


def true_surface_samples(obj: SDFObject, spacing_m: float | None = None) -> np.ndarray:
    """Samples of the true surface (cached on the object); in 3D without the face on the table."""
    if spacing_m is None:
        spacing_m = 0.001 if obj.dim == 2 else 0.003
    cache = obj.__dict__.setdefault("_true_surface_cache", {})
    key = round(float(spacing_m), 12)
    if key not in cache:
        s = obj.surface_samples(spacing_m)
        if obj.dim == 3:
            low = np.nonzero(s[:, 2] < TABLE_TOL_M)[0]
            on_table = low[obj.gradient(s[low])[:, 2] < -0.999]
            s = np.delete(s, on_table, axis=0)
        cache[key] = s
    return cache[key]


def surface_error_stats(obj: SDFObject, estimated_surface_points: np.ndarray,
                        spacing_m: float | None = None) -> SurfaceError:
    """All surface distances of :class:`SurfaceError` (estimated points: (K, >= dim))."""
    est = np.asarray(estimated_surface_points, dtype=float)
    if est.ndim != 2 or est.shape[1] < obj.dim or len(est) == 0:
        raise ValueError(f"estimated_surface_points must be a non-empty (K, >= {obj.dim}) array, got shape {est.shape}")
    est = est[:, :obj.dim]
    if not np.all(np.isfinite(est)):
        raise ValueError("estimated_surface_points contain NaN or inf")
    true = true_surface_samples(obj, spacing_m)
    d_true, _ = cKDTree(est).query(true)
    d_est = np.abs(obj.sdf(est))
    return SurfaceError(
        mean_m=float(d_true.mean()), max_m=float(d_true.max()),
        est_to_true_mean_m=float(d_est.mean()), est_to_true_max_m=float(d_est.max()),
        symmetric_mean_m=float(0.5 * (d_true.mean() + d_est.mean())),
        hausdorff_m=float(max(d_true.max(), d_est.max())),
    )


def surface_error(obj: SDFObject, estimated_surface_points: np.ndarray, spacing_m: float | None = None) -> float:
    """Mean distance from the true surface to the estimated zero level set [m].

    True-surface samples (:func:`true_surface_samples`) → nearest estimated
    point (cKDTree). The estimated level set should be sampled densely (well
    below the error you want to resolve).
    """
    return surface_error_stats(obj, estimated_surface_points, spacing_m).mean_m
