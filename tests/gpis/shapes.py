"""Analytic test shapes written for these tests (signed distance-like, < 0 inside)."""

from __future__ import annotations

import numpy as np

CENTRE_2D = np.array([0.5, 0.0])
CENTRE_3D = np.array([0.5, 0.0, 0.07])


def circle_sdf(p: np.ndarray, r: float = 0.05) -> np.ndarray:
    return np.linalg.norm(p[:, :2] - CENTRE_2D, axis=1) - r


def sphere_sdf(p: np.ndarray, r: float = 0.05) -> np.ndarray:
    return np.linalg.norm(p - CENTRE_3D, axis=1) - r


def star_radius(theta: np.ndarray, r0: float = 0.05, amp: float = 0.35, arms: int = 5) -> np.ndarray:
    """Polar star r(theta) = r0 (1 + amp cos(arms theta))."""
    return r0 * (1 + amp * np.cos(arms * theta))


def star_inside(p: np.ndarray) -> np.ndarray:
    u = p[:, :2] - CENTRE_2D
    return np.linalg.norm(u, axis=1) < star_radius(np.arctan2(u[:, 1], u[:, 0]))


def star_surface(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) on the star and unit outward normals (from the polar curve)."""
    r = star_radius(theta)
    dr = -0.05 * 0.35 * 5 * np.sin(5 * theta)
    pts = CENTRE_2D + np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1)
    tangent = np.stack([dr * np.cos(theta) - r * np.sin(theta), dr * np.sin(theta) + r * np.cos(theta)], axis=1)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)  # rotate -90 deg: outward for CCW
    return pts, normal / np.linalg.norm(normal, axis=1, keepdims=True)


def fibonacci_sphere(n: int) -> np.ndarray:
    """n unit vectors spread over the sphere."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def lobed_radius(u: np.ndarray, r0: float = 0.05, amp: float = 0.3, lobes: int = 3) -> np.ndarray:
    """Non-convex 3D body, radius along unit directions u (N, 3): r0 (1 + amp cos(lobes theta) sin^2 phi)."""
    th = np.arctan2(u[:, 1], u[:, 0])
    return r0 * (1 + amp * np.cos(lobes * th) * (1 - np.clip(u[:, 2], -1, 1) ** 2))


def lobed_sdf(p: np.ndarray) -> np.ndarray:
    """|p - c| - r(direction): < 0 inside the lobed body (not a true distance)."""
    v = p - CENTRE_3D
    r = np.linalg.norm(v, axis=1)
    return r - lobed_radius(v / np.maximum(r, 1e-12)[:, None])


def lobed_surface(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """About n points (N, 3) on the lobed body above z = 3 mm, jittered Fibonacci directions
    (seeded), with unit outward normals by central differences of lobed_sdf."""
    rng = np.random.default_rng(seed)
    d = fibonacci_sphere(n) + rng.normal(scale=0.02, size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = CENTRE_3D + lobed_radius(d)[:, None] * d
    p = p[p[:, 2] > 0.003]
    e = 1e-6
    g = np.stack([(lobed_sdf(p + e * np.eye(3)[i]) - lobed_sdf(p - e * np.eye(3)[i])) / (2 * e) for i in range(3)], 1)
    return p, g / np.linalg.norm(g, axis=1, keepdims=True)
