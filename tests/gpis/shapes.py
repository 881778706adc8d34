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
