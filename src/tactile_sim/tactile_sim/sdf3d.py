"""Exact 3D signed distance primitives (object-local frame, metres; < 0 inside).

All functions take ``p`` of shape (N, 3) and return (N,) (Inigo Quilez's
3D distance functions). Extrusion and revolution lift an exact 2D SDF to an
exact 3D one.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

Sdf2D = Callable[[np.ndarray], np.ndarray]


def sphere(p: np.ndarray, radius_m: float) -> np.ndarray:
    """d = |p| − r."""
    return np.linalg.norm(p, axis=1) - radius_m


def box(p: np.ndarray, half_m: tuple[float, float, float]) -> np.ndarray:
    """Axis-aligned box: q = |p| − h;  d = ‖max(q, 0)‖ + min(max_i q_i, 0)."""
    q = np.abs(p) - np.asarray(half_m)
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(np.max(q, axis=1), 0.0)


def cap(w_xy: np.ndarray, w_z: np.ndarray) -> np.ndarray:
    """Combine a 2D distance and an axial slab distance (exact intersection of a prism)."""
    w = np.column_stack([w_xy, w_z])
    return np.minimum(np.max(w, axis=1), 0.0) + np.linalg.norm(np.maximum(w, 0.0), axis=1)


def capped_cylinder(p: np.ndarray, radius_m: float, half_height_m: float) -> np.ndarray:
    """Cylinder about z of radius r and |z| ≤ h."""
    return cap(np.hypot(p[:, 0], p[:, 1]) - radius_m, np.abs(p[:, 2]) - half_height_m)


def capsule(p: np.ndarray, a: np.ndarray, b: np.ndarray, radius_m: float) -> np.ndarray:
    """All points within r of the segment a–b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ba = b - a
    pa = p - a
    h = np.clip(pa @ ba / float(ba @ ba), 0.0, 1.0)
    return np.linalg.norm(pa - h[:, None] * ba, axis=1) - radius_m


def torus(p: np.ndarray, major_radius_m: float, minor_radius_m: float) -> np.ndarray:
    """Torus in the x–y plane: q = (|p_xy| − R, z);  d = |q| − r."""
    return np.hypot(np.hypot(p[:, 0], p[:, 1]) - major_radius_m, p[:, 2]) - minor_radius_m


def extrude(p: np.ndarray, sdf2d: Sdf2D, axes: tuple[int, int, int], half_length_m: float) -> np.ndarray:
    """Right prism: the 2D shape in coordinates (p[axes[0]], p[axes[1]]) extruded ±h along p[axes[2]]."""
    return cap(sdf2d(p[:, list(axes[:2])]), np.abs(p[:, axes[2]]) - half_length_m)


def revolve(p: np.ndarray, sdf2d: Sdf2D) -> np.ndarray:
    """Solid of revolution about z of a 2D cross-section given in (r, z).

    Exact when the cross-section is mirror-symmetric about r = 0 (then the
    closest boundary point of a query with r ≥ 0 lies on the r ≥ 0 side, and
    the axis itself is no boundary).
    """
    return sdf2d(np.column_stack([np.hypot(p[:, 0], p[:, 1]), p[:, 2]]))
