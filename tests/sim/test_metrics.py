"""Metrics vs closed forms: lens-area IoU, concentric-ball IoU, offset-circle surface error."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_sim.metrics import evaluation_lattice, iou, surface_error, surface_error_stats
from tactile_sim.objects import make_object

WORKSPACE_2D = np.array([[0.35, -0.15], [0.65, 0.15]])
WORKSPACE_3D = np.array([[0.35, -0.15, -0.05], [0.65, 0.15, 0.22]])
RNG_SURF = np.random.default_rng(3)


def lens_area(r1: float, r2: float, d: float) -> float:
    """Area of the intersection of two discs with centre distance d (closed form)."""
    a1 = r1**2 * np.arccos((d**2 + r1**2 - r2**2) / (2 * d * r1))
    a2 = r2**2 * np.arccos((d**2 + r2**2 - r1**2) / (2 * d * r2))
    tri = 0.5 * np.sqrt((-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2))
    return a1 + a2 - tri


def test_evaluation_lattice_cells():
    pts = evaluation_lattice(WORKSPACE_2D, 0.01)
    assert pts.shape == (30 * 30, 2)
    np.testing.assert_allclose(pts[0], [0.355, -0.145])
    np.testing.assert_allclose(pts[1] - pts[0], [0.0, 0.01])  # C order: last axis fastest
    p3 = evaluation_lattice(WORKSPACE_3D, 0.01)
    assert p3[:, 2].min() > 0 and p3.shape == (30 * 30 * 22, 3)
    with pytest.raises(ValueError, match="resolution_m must be positive"):
        evaluation_lattice(WORKSPACE_2D, 0.0)
    with pytest.raises(ValueError, match="bounds must be"):
        evaluation_lattice(np.zeros(4), 0.01)


def test_iou_of_offset_circles_is_the_lens_formula():
    r_true, r_est, d = 0.04, 0.03, 0.035
    obj = make_object("circle", center_xy_m=(0.5, 0.0))
    est_center = np.array([0.5 + d, 0.0])
    pts = evaluation_lattice(WORKSPACE_2D, 0.0005)
    got = iou(lambda p: np.linalg.norm(p[:, :2] - est_center, axis=1) < r_est, obj, pts)
    a = lens_area(r_true, r_est, d)
    expected = a / (np.pi * r_true**2 + np.pi * r_est**2 - a)
    assert got == pytest.approx(expected, abs=2e-3)
    # Disjoint and identical shapes.
    assert iou(lambda p: np.zeros(len(p), bool), obj, pts) == 0.0
    star = make_object("star")
    assert iou(star.inside, star, pts) == 1.0


def test_iou_in_3d_concentric_balls():
    obj = make_object("sphere", mode="3d")
    c = np.array([0.5, 0.0, 0.05])
    pts = evaluation_lattice(WORKSPACE_3D, 0.002)
    got = iou(lambda p: np.linalg.norm(p - c, axis=1) < 0.04, obj, pts)
    assert got == pytest.approx((0.04 / 0.05) ** 3, abs=0.01)


def test_iou_rejects_bad_inside_test():
    obj = make_object("circle")
    pts = evaluation_lattice(WORKSPACE_2D, 0.01)
    with pytest.raises(ValueError, match="inside_est returned shape"):
        iou(lambda p: np.zeros(3, bool), obj, pts)


@pytest.mark.parametrize("d", [0.004, -0.006])
def test_surface_error_of_concentric_circles_is_the_radius_difference(d):
    r = 0.04
    obj = make_object("circle", center_xy_m=(0.5, 0.0))
    t = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    est = np.column_stack([0.5 + (r + d) * np.cos(t), (r + d) * np.sin(t), np.full_like(t, 0.06)])
    assert surface_error(obj, est) == pytest.approx(abs(d), abs=2e-5)
    stats = surface_error_stats(obj, est)
    assert stats.est_to_true_mean_m == pytest.approx(abs(d), abs=1e-12)
    assert stats.hausdorff_m == pytest.approx(abs(d), abs=2e-5)


def test_surface_error_detects_a_missing_part():
    """A square estimate of a circle: the directed mean is the mean gap, not zero."""
    obj = make_object("circle", center_xy_m=(0.5, 0.0))
    t = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    half = np.column_stack([0.5 + 0.04 * np.cos(t), 0.04 * np.sin(t)])[: len(t) // 2]  # upper half only
    stats = surface_error_stats(obj, half)
    # True points on the lower half are at distance 2r|sin(phi/2)|-ish from the nearest end: clearly > 1 cm.
    assert stats.mean_m > 0.01 and stats.est_to_true_mean_m < 1e-12


def test_surface_error_of_concentric_spheres():
    d = 0.005
    obj = make_object("sphere", mode="3d")
    n = 200_000
    k = np.arange(n) + 0.5
    phi, theta = np.arccos(1 - 2 * k / n), np.pi * (1 + 5**0.5) * k
    u = np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])
    est = np.array([0.5, 0.0, 0.05]) + (0.05 + d) * u
    assert surface_error(obj, est) == pytest.approx(d, rel=0.02)
    with pytest.raises(ValueError, match="non-empty"):
        surface_error(obj, np.zeros((0, 3)))


def test_3d_surface_error_ignores_the_face_on_the_table():
    """The face the box stands on cannot be touched: an estimate without it has zero error."""
    obj = make_object("box", mode="3d")
    side = np.array([0.5, 0.0, 0.05]) + RNG_SURF.uniform(-1, 1, size=(60000, 3)) * [0.04, 0.03, 0.05]
    k = RNG_SURF.integers(0, 5, len(side))  # project onto one of the 5 faces above the table
    axis, sign = np.array([0, 0, 1, 1, 2])[k], np.array([-1, 1, -1, 1, 1])[k]
    side[np.arange(len(side)), axis] = np.array([0.5, 0.0, 0.05])[axis] + sign * np.array([0.04, 0.03, 0.05])[axis]
    assert surface_error(obj, side) < 0.002
    top_only = side[side[:, 2] > 0.0999]
    assert surface_error(obj, top_only) > 0.02


def test_iou_cache_matches_direct_evaluation():
    obj = make_object("torus", mode="3d", yaw_rad=0.3)
    pts = evaluation_lattice(WORKSPACE_3D, 0.006)
    direct = obj.sdf(pts) < 0
    est = lambda p: np.linalg.norm(p - [0.5, 0.0, 0.018], axis=1) < 0.05  # noqa: E731
    expected = np.count_nonzero(direct & est(pts)) / np.count_nonzero(direct | est(pts))
    assert iou(est, obj, pts) == pytest.approx(expected, abs=1e-15)
    assert iou(est, obj, pts) == pytest.approx(expected, abs=1e-15)  # cached
