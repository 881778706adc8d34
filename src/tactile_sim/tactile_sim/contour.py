"""Contour length and convexity of a 2D section, the yardsticks of sliding (ROS-free).

A finger that slides senses the whole contour in one lap, so travel is also
reported in contour lengths ("laps"). The contour is the zero level set of
the object's SDF on a square lattice of spacing ``spacing_m`` over its
bounds plus a margin (marching squares, ``contourpy``); its length is the
polyline length (error O(spacing²) on smooth parts, exact on straight
edges up to the corner cuts). Convexity: the section's area over its convex
hull's area (1 for a convex section).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from contourpy import contour_generator
from scipy.spatial import ConvexHull


def _lines(obj: Any, spacing_m: float) -> list[np.ndarray]:
    if getattr(obj, "dim", 2) != 2:
        raise ValueError(f"contour length needs a 2D section, got a {obj.dim}D object")
    if not spacing_m > 0:
        raise ValueError(f"spacing_m = {spacing_m}: must be > 0")
    lo, hi = np.asarray(obj.bounds, dtype=float) + np.array([[-1.0], [1.0]]) * 4 * spacing_m
    xs = np.arange(lo[0], hi[0] + spacing_m, spacing_m)
    ys = np.arange(lo[1], hi[1] + spacing_m, spacing_m)
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    d = np.asarray(obj.sdf(np.column_stack([X.ravel(), Y.ravel()])), dtype=float).reshape(X.shape)
    return [np.asarray(line) for line in contour_generator(xs, ys, d).lines(0.0)]


def contour_length_m(obj: Any, spacing_m: float = 0.0005) -> float:
    """Length of the 2D section's boundary (all its loops), metres."""
    return float(sum(np.linalg.norm(np.diff(line, axis=0), axis=1).sum() for line in _lines(obj, spacing_m)))


def convexity(obj: Any, spacing_m: float = 0.0005) -> float:
    """Area of the section over the area of its convex hull (≤ 1; 1 = convex)."""
    lines = _lines(obj, spacing_m)
    area = sum(abs(0.5 * np.sum(l[:-1, 0] * l[1:, 1] - l[1:, 0] * l[:-1, 1])) for l in lines)
    hull = ConvexHull(np.vstack(lines)).volume  # in 2D, volume is the area
    return float(area / hull)


def is_convex(obj: Any, tolerance: float = 0.01) -> bool:
    """Convex up to ``tolerance`` of the hull's area (the rounded square is; the star, L and C are not)."""
    return convexity(obj) >= 1.0 - tolerance
