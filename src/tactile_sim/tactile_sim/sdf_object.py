"""The object interface: an SDF in the world frame, its pose on the table, prisms.

``sdf(p)`` (N, dim) → (N,) signed distance (< 0 inside), ``gradient(p)``
(N, dim) unit outward normals, ``bounds`` (2, dim), ``name``, ``dim``.
Placement (docs/architecture.md): the object-local origin goes to
``center_xy_m`` on the table top, rotated by ``yaw_rad`` about z, sizes
multiplied by ``scale``; 3D solids are intersected with z ≥ 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from tactile_sim import sdf3d
from tactile_sim.surface import project_to_surface

LocalSdf = Callable[[np.ndarray], np.ndarray]

#: Central-difference step for numerical gradients [m].
FD_STEP_M = 1e-6


class SDFObject:
    """A solid in the world frame given by its signed distance function.

    Subclasses implement :meth:`sdf`; :meth:`gradient` defaults to central
    differences of the SDF, normalised.
    """

    name: str
    dim: int
    bounds: np.ndarray

    def sdf(self, p: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def gradient(self, p: np.ndarray) -> np.ndarray:
        """Unit outward normal field ∇d/‖∇d‖ by central differences (step FD_STEP_M)."""
        p = self._check(p)
        n = len(p)
        offsets = np.eye(self.dim) * FD_STEP_M
        stacked = np.concatenate([p + o for o in offsets] + [p - o for o in offsets])
        d = self.sdf(stacked).reshape(2, self.dim, n)
        g = ((d[0] - d[1]) / (2.0 * FD_STEP_M)).T
        return _normalise(g)

    def inside(self, p: np.ndarray) -> np.ndarray:
        """Boolean (N,): sdf(p) < 0."""
        return self.sdf(p) < 0.0

    def surface_samples(self, spacing_m: float = 0.002) -> np.ndarray:
        """Points of the zero level set, about one per ``spacing_m`` lattice cell (cached).

        Lattice nodes within one cell of the surface (found coarse-to-fine,
        using |∇d| ≤ 1) are projected onto it with p ← p − d(p)·∇d(p).
        Points that do not converge to |d| < 1e-7 m are dropped.
        """
        key = round(float(spacing_m), 12)
        cache = self.__dict__.setdefault("_surface_cache", {})
        if key not in cache:
            cache[key] = project_to_surface(self, float(spacing_m))
        return cache[key]

    def _check(self, p: np.ndarray) -> np.ndarray:
        a = np.asarray(p, dtype=float)
        if a.ndim == 1 and a.shape[0] == self.dim:
            a = a[None, :]
        if a.ndim != 2 or a.shape[1] != self.dim:
            raise ValueError(f"object '{self.name}' is {self.dim}D: expected points of shape (N, {self.dim}), got {np.shape(p)}")
        return a

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, dim={self.dim}, bounds={self.bounds.tolist()})"


def _normalise(g: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(g, axis=1, keepdims=True)
    return g / np.where(norm > 0.0, norm, 1.0)


@dataclass(frozen=True)
class Pose:
    """Object pose on the table: local origin at (x, y, 0), yaw about z, uniform scale."""

    center_xy_m: tuple[float, float] = (0.50, 0.0)
    yaw_rad: float = 0.0
    scale: float = 1.0

    def to_local(self, p: np.ndarray) -> np.ndarray:
        """World → object-local (unscaled): q = R(−yaw)(p − c) / s; z is kept (table at 0)."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        x = p[:, 0] - self.center_xy_m[0]
        y = p[:, 1] - self.center_xy_m[1]
        q = np.empty_like(p)
        q[:, 0] = c * x + s * y
        q[:, 1] = -s * x + c * y
        if p.shape[1] == 3:
            q[:, 2] = p[:, 2]
        return q / self.scale

    def vector_to_world(self, v: np.ndarray) -> np.ndarray:
        """Rotate local direction vectors to the world frame (yaw only)."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        out = v.copy()
        out[:, 0] = c * v[:, 0] - s * v[:, 1]
        out[:, 1] = s * v[:, 0] + c * v[:, 1]
        return out

    def bounds_to_world(self, local_bounds: np.ndarray) -> np.ndarray:
        """Axis-aligned world box of a local box (corners rotated, scaled, shifted)."""
        lo, hi = np.asarray(local_bounds, float)
        corners = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]) * self.scale
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        xy = corners @ np.array([[c, s], [-s, c]]) + np.asarray(self.center_xy_m)
        out = np.vstack([xy.min(axis=0), xy.max(axis=0)])
        if len(lo) == 3:
            out = np.column_stack([out, [lo[2] * self.scale, hi[2] * self.scale]])
        return out


class PlacedShape(SDFObject):
    """An object-local SDF placed on the table (see module docstring).

    sdf(p) = s · d_local(q) with q = pose.to_local(p); in 3D additionally
    max(·, −z) (nothing below the table top).
    """

    def __init__(self, name: str, dim: int, local_sdf: LocalSdf, local_bounds: np.ndarray,
                 pose: Pose = Pose(), local_gradient: LocalSdf | None = None) -> None:
        self.name = name
        self.dim = dim
        self.pose = pose
        self._local_sdf = local_sdf
        self._local_gradient = local_gradient
        self.local_bounds = np.asarray(local_bounds, float)
        self.bounds = pose.bounds_to_world(self.local_bounds)
        if dim == 3:
            self.bounds[0, 2] = max(self.bounds[0, 2], 0.0)

    def sdf(self, p: np.ndarray) -> np.ndarray:
        p = self._check(p)
        d = self.pose.scale * self._local_sdf(self.pose.to_local(p))
        if self.dim == 3:
            d = np.maximum(d, -p[:, 2])
        return d

    def gradient(self, p: np.ndarray) -> np.ndarray:
        if self._local_gradient is None:
            return super().gradient(p)
        p = self._check(p)
        q = self.pose.to_local(p)
        g = self.pose.vector_to_world(self._local_gradient(q))
        if self.dim == 3:
            # The table face can only be the closest one below z = 0 (the solid lies in z >= 0).
            below = np.nonzero(p[:, 2] < 0.0)[0]
            if len(below):
                table = -p[below, 2] > self.pose.scale * self._local_sdf(q[below])
                g[below[table]] = (0.0, 0.0, -1.0)
        return _normalise(g)


class Prism(SDFObject):
    """The right prism 0 ≤ z ≤ h over a 2D object (exact extrusion SDF)."""

    def __init__(self, section: SDFObject, height_m: float) -> None:
        if section.dim != 2:
            raise ValueError(f"a prism needs a 2D cross-section, '{section.name}' is {section.dim}D")
        self.section = section
        self.height_m = float(height_m)
        self.name = section.name
        self.dim = 3
        self.bounds = np.column_stack([section.bounds, [0.0, self.height_m]])

    def sdf(self, p: np.ndarray) -> np.ndarray:
        p = self._check(p)
        half = 0.5 * self.height_m
        return sdf3d.cap(self.section.sdf(p[:, :2]), np.abs(p[:, 2] - half) - half)
