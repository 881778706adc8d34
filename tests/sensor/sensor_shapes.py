"""Small analytic objects with the tactile_sim object interface (dim, sdf, gradient), for tests.

Written here, independently of the package, so the tests' ground truth does
not come from the code under test.
"""

from __future__ import annotations

import numpy as np


class Plane:
    """Half-space {(x - p0) . n < 0}: n is the unit outward normal."""

    def __init__(self, point, normal, dim: int = 3) -> None:
        self.dim = dim
        self.p0 = np.asarray(point, dtype=float)[:dim]
        n = np.asarray(normal, dtype=float)[:dim]
        self.n = n / np.linalg.norm(n)
        self.name = "plane"

    def sdf(self, p):
        return (np.asarray(p)[:, : self.dim] - self.p0) @ self.n

    def gradient(self, p):
        return np.tile(self.n, (len(p), 1))

    def closest_point(self, x):
        x = np.asarray(x, dtype=float)[: self.dim]
        return x - ((x - self.p0) @ self.n) * self.n


class Cylinder:
    """Infinite vertical cylinder (3D) or disc (2D) of radius r around (cx, cy)."""

    def __init__(self, centre_xy, radius_m: float, dim: int = 3) -> None:
        self.dim = dim
        self.c = np.asarray(centre_xy, dtype=float)[:2]
        self.r = float(radius_m)
        self.name = "cylinder"

    def sdf(self, p):
        return np.linalg.norm(np.asarray(p)[:, :2] - self.c, axis=1) - self.r

    def gradient(self, p):
        d = np.asarray(p)[:, :2] - self.c
        g = d / np.linalg.norm(d, axis=1, keepdims=True)
        return g if self.dim == 2 else np.hstack([g, np.zeros((len(p), 1))])

    def closest_point(self, x):
        x = np.asarray(x, dtype=float)
        d = x[:2] - self.c
        out = x.copy()
        out[:2] = self.c + self.r * d / np.linalg.norm(d)
        return out


class Sphere:
    """Ball of radius r around a centre (3D)."""

    def __init__(self, centre, radius_m: float) -> None:
        self.dim = 3
        self.c = np.asarray(centre, dtype=float)
        self.r = float(radius_m)
        self.name = "sphere"

    def sdf(self, p):
        return np.linalg.norm(np.asarray(p) - self.c, axis=1) - self.r

    def gradient(self, p):
        d = np.asarray(p) - self.c
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def closest_point(self, x):
        d = np.asarray(x, dtype=float) - self.c
        return self.c + self.r * d / np.linalg.norm(d)


def rotation_about(axis, angle_rad: float) -> np.ndarray:
    """Rodrigues rotation matrix."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1 - np.cos(angle_rad)) * K @ K
