"""The finger-reachable solid (closing by a ball of the tip radius) vs analytic cases."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from tactile_sim import sdf2d, sdf3d
from tactile_sim.metrics import evaluation_lattice, iou, reachable_inside, reachable_iou, true_inside
from tactile_sim.objects import PlacedShape, Pose, make_object

R_TIP = 0.01
Z_MIN = 0.015  # table 0 + margin 5 mm + tip radius
WS2 = np.array([[0.35, -0.15], [0.65, 0.15]])
WS3 = np.array([[0.35, -0.15, 0.0], [0.65, 0.15, 0.22]])
FILLET_90_M2 = (1.0 - np.pi / 4.0) * R_TIP**2  # area a ball of radius r cannot reach in a 90° inner corner


def slot_object(width_m: float, depth_m: float = 0.07) -> PlacedShape:
    """A 10 cm square with a rectangular slot from its right side (width x depth)."""
    w = width_m / 2
    v = np.array([(0, 0), (0.1, 0), (0.1, 0.05 - w), (0.1 - depth_m, 0.05 - w), (0.1 - depth_m, 0.05 + w),
                  (0.1, 0.05 + w), (0.1, 0.1), (0, 0.1)]) - 0.05
    return PlacedShape("slot", 2, partial(sdf2d.polygon, vertices=v), np.vstack([v.min(0), v.max(0)]), Pose())


@pytest.mark.parametrize("width_m", [0.012, 0.018])
def test_a_slot_narrower_than_the_finger_is_filled(width_m):
    pts = evaluation_lattice(WS2, 0.001)
    obj = slot_object(width_m)
    added = np.count_nonzero(reachable_inside(obj, pts, R_TIP) & ~true_inside(obj, pts)) * 1e-6
    # All of the slot but the mouth, where a ball reaches in by at most r - sqrt(r² - (w/2)²).
    mouth = R_TIP - np.sqrt(R_TIP**2 - (width_m / 2) ** 2)
    assert added == pytest.approx(width_m * (0.07 - mouth), rel=0.04)


@pytest.mark.parametrize("width_m", [0.026, 0.04])
def test_a_wider_slot_keeps_only_its_corner_fillets(width_m):
    pts = evaluation_lattice(WS2, 0.001)
    obj = slot_object(width_m)
    added = np.count_nonzero(reachable_inside(obj, pts, R_TIP) & ~true_inside(obj, pts)) * 1e-6
    assert added == pytest.approx(2 * FILLET_90_M2, rel=0.15)


def test_the_inner_corner_of_the_l_is_one_fillet():
    pts = evaluation_lattice(WS2, 0.001)
    obj = make_object("l_shape")
    added = np.count_nonzero(reachable_inside(obj, pts, R_TIP) & ~true_inside(obj, pts)) * 1e-6
    assert added == pytest.approx(FILLET_90_M2, rel=0.15)


@pytest.mark.parametrize("name", ["circle", "ellipse", "rounded_square", "triangle", "kidney"])
def test_convex_sections_are_unchanged(name):
    """The kidney's concave side has radius 4.5 - 2.2 = 2.3 cm > r: nothing to fill either."""
    pts = evaluation_lattice(WS2, 0.002)
    obj = make_object(name, yaw_rad=0.3)
    assert np.array_equal(reachable_inside(obj, pts, R_TIP), true_inside(obj, pts))
    assert reachable_iou(obj.inside, obj, pts, R_TIP) == 1.0


def test_an_enclosed_hole_is_not_reachable():
    """A ring: the finger cannot get into the closed hole, however large."""
    ring = PlacedShape("ring", 2, lambda q: np.maximum(sdf2d.circle(q, 0.06), -sdf2d.circle(q, 0.04)),
                       np.array([[-0.06, -0.06], [0.06, 0.06]]), Pose())
    pts = evaluation_lattice(WS2, 0.002)
    reach = reachable_inside(ring, pts, R_TIP)
    disc = np.linalg.norm(pts - (0.5, 0.0), axis=1) < 0.06
    assert np.array_equal(reach, disc)


@pytest.mark.parametrize("name", ["box", "cylinder", "cone", "torus"])
def test_3d_solids_without_undercuts_are_unchanged_above_the_band(name):
    pts = evaluation_lattice(WS3, 0.004)
    obj = make_object(name, mode="3d")
    counted = pts[:, 2] >= Z_MIN
    assert np.array_equal(reachable_inside(obj, pts, R_TIP, Z_MIN)[counted], true_inside(obj, pts)[counted])


def test_the_band_below_the_lowest_tip_is_left_out():
    """An estimate that is right above z_min and wrong below scores 1 on the reachable IoU only."""
    pts = evaluation_lattice(WS3, 0.004)
    obj = make_object("box", mode="3d")
    est = lambda p: obj.inside(p) & (p[:, 2] >= Z_MIN)  # noqa: E731 - misses the bottom 1.5 cm
    assert reachable_iou(est, obj, pts, R_TIP, Z_MIN) == 1.0
    assert iou(est, obj, pts) == pytest.approx(1.0 - 0.016 / 0.10, abs=0.01)  # nodes at z < 0.015: 4 of 25 layers


@pytest.mark.parametrize("clearance_m, filled", [(0.02, True), (0.06, False)])
def test_under_a_slab_the_tip_must_fit_above_its_lowest_height(clearance_m, filled):
    """A 12 x 12 cm slab on a 2 cm pillar: under it the tip centre needs z ∈ [z_min, clearance − r]."""
    t = 0.02
    def fn(q):  # noqa: E306
        slab = sdf3d.box(q - (0, 0, clearance_m + t / 2), (0.06, 0.06, t / 2))
        pillar = sdf3d.box(q - (0, 0, clearance_m / 2), (0.01, 0.01, clearance_m / 2))
        return np.minimum(slab, pillar)
    obj = PlacedShape("slab", 3, fn, np.array([[-0.06, -0.06, 0.0], [0.06, 0.06, clearance_m + t]]), Pose())
    pts = evaluation_lattice(WS3, 0.004)
    reach = reachable_inside(obj, pts, R_TIP, Z_MIN)
    probe = np.array([[0.5 + 0.04, 0.0, 0.5 * (Z_MIN + clearance_m)]])  # under the slab, away from the pillar
    k = np.argmin(np.linalg.norm(pts - probe, axis=1))
    assert obj.sdf(pts[k:k + 1])[0] > 0 and bool(reach[k]) == filled


def test_bad_inputs():
    obj = make_object("circle")
    pts = evaluation_lattice(WS2, 0.01)
    with pytest.raises(ValueError, match="tip_radius_m must be positive"):
        reachable_inside(obj, pts, 0.0)
    with pytest.raises(ValueError, match="not a regular grid"):
        reachable_inside(obj, pts[:-1], R_TIP)
    with pytest.raises(ValueError, match="needs min_tip_z_m"):
        reachable_inside(make_object("box", mode="3d"), evaluation_lattice(WS3, 0.01), R_TIP)
