"""The partial-volume IoU against closed-form volumes (offset boxes, cylinders, balls, discs)."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from tactile_sim import sdf2d, sdf3d
from tactile_sim.metrics import (cell_fraction_below_zero, evaluation_lattice, iou, lattice_axes,
                                 partial_volume_iou, reachable_iou)
from tactile_sim.objects import PlacedShape, Pose, make_object

R_TIP = 0.01
Z_MIN = 0.015
WS2 = np.array([[0.35, -0.15], [0.65, 0.15]])
WS3 = np.array([[0.35, -0.15, 0.0], [0.65, 0.15, 0.22]])


def shrunk_field(obj, pts: np.ndarray, shrink_m: float) -> np.ndarray:
    """The object's sdf + shrink_m at the lattice points (+inf away from it): the field of the solid
    eroded by shrink_m, an estimate whose every surface lies shrink_m inside the true one."""
    f = np.full(len(pts), np.inf)
    near = np.all((pts >= obj.bounds[0] - 0.02) & (pts <= obj.bounds[1] + 0.02), axis=1)
    f[near] = obj.sdf(pts[near]) + shrink_m
    return f


def analytic_cases(rng: np.random.Generator):
    """(object, IoU of it against its erosion by d as a function of d): boxes, upright cylinders on the
    table and balls, sizes 1.6–8 cm, placed at random sub-cell offsets (the erosion's bottom face of
    a solid standing on the table rises by d too)."""
    for _ in range(4):
        o = rng.uniform(-0.002, 0.002, 3)
        half = rng.uniform(0.015, 0.04, 3)
        r, hh = rng.uniform(0.008, 0.03), rng.uniform(0.02, 0.06)
        pose = Pose(center_xy_m=(0.5 + o[0], o[1]))
        yield (PlacedShape("box", 3, lambda q, h=half: sdf3d.box(q - (0, 0, h[2]), tuple(h)),
                           np.array([-half, half]) + [0, 0, half[2]], pose),
               lambda d, h=half: np.prod(h - d) / np.prod(h))
        yield (PlacedShape("cyl", 3, lambda q, r=r, hh=hh: sdf3d.capped_cylinder(q - (0, 0, hh), r, hh),
                           np.array([[-r, -r, 0], [r, r, 2 * hh]]), pose),
               lambda d, r=r, hh=hh: (r - d) ** 2 * (hh - d) / (r * r * hh))
        yield (PlacedShape("ball", 3, lambda q, r=r, z=0.06 + o[2]: sdf3d.sphere(q - (0, 0, z), r),
                           np.array([[-r, -r, 0.06 + o[2] - r], [r, r, 0.06 + o[2] + r]]), pose),
               lambda d, r=r: ((r - d) / r) ** 3)


def test_against_closed_form_volumes_the_error_is_a_fraction_of_the_centres():
    """Offsets of 0.16–1 mm on a 4 mm lattice: the partial-volume IoU is within 0.01 of the closed
    form in every case, where counting cell centres errs by more than 0.05 in some (a face that lies
    a hair from a layer of centres flips the whole layer)."""
    pts = evaluation_lattice(WS3, 0.004)
    pv_err, centre_err = [], []
    for obj, ratio in analytic_cases(np.random.default_rng(1)):
        for d in (0.00016, 0.0005, 0.001):
            f = shrunk_field(obj, pts, d)
            pv_err.append(partial_volume_iou(f, obj, pts) - ratio(d))
            centre_err.append(iou(lambda p: f < 0, obj, pts) - ratio(d))
    assert np.max(np.abs(pv_err)) < 0.01
    assert np.sqrt(np.mean(np.square(pv_err))) < 0.004
    assert np.max(np.abs(centre_err)) > 0.05


def test_offset_discs_in_2d_are_the_lens_formula():
    """Two discs 3.5 mm apart on a coarse 4 mm lattice (2D counts area)."""
    r1, r2, d = 0.04, 0.03, 0.0035
    obj = make_object("circle", center_xy_m=(0.5, 0.0))
    pts = evaluation_lattice(WS2, 0.004)
    f = np.linalg.norm(pts - (0.5 + d, 0.0), axis=1) - r2
    a = np.pi * r2**2  # the smaller disc lies wholly inside the larger (d < r1 − r2)
    assert partial_volume_iou(f, obj, pts) == pytest.approx(a / (np.pi * r1**2), abs=0.005)


@pytest.mark.parametrize("name, mode, ws", [("star", "2d", WS2), ("gen3d-001-letter_prism", "3d", WS3)])
def test_a_perfect_estimate_scores_one_and_one_cell_size_is_the_centres(name, mode, ws):
    obj = make_object(name, mode=mode)
    pts = evaluation_lattice(ws, 0.004)
    f = shrunk_field(obj, pts, 0.0)
    assert partial_volume_iou(f, obj, pts) == 1.0
    # on a fine lattice the fractions matter little: both counts agree
    fine = evaluation_lattice(ws, 0.001) if mode == "2d" else None
    if fine is not None:
        g = shrunk_field(obj, fine, 0.0007)
        assert partial_volume_iou(g, obj, fine) == pytest.approx(iou(lambda p: g < 0, obj, fine), abs=0.003)


def test_reachable_counts_above_the_lowest_tip_height_by_fraction():
    """An upright cylinder (convex: the reachable solid is the true one above z_min): the estimate
    eroded by d against the part above Z_MIN, whose height straddles lattice layers."""
    r, hh, d = 0.02, 0.0412, 0.0005
    obj = PlacedShape("cyl", 3, lambda q: sdf3d.capped_cylinder(q - (0, 0, hh), r, hh),
                      np.array([[-r, -r, 0], [r, r, 2 * hh]]), Pose())
    pts = evaluation_lattice(WS3, 0.004)
    f = shrunk_field(obj, pts, d)
    expected = (r - d) ** 2 * (2 * hh - d - Z_MIN) / (r * r * (2 * hh - Z_MIN))
    assert partial_volume_iou(f, obj, pts, R_TIP, Z_MIN) == pytest.approx(expected, abs=0.005)
    # and an estimate that is right above Z_MIN and wrong further below it (all solid) still scores 1
    g = np.where(pts[:, 2] < Z_MIN - 0.008, -1.0, shrunk_field(obj, pts, 0.0))
    assert partial_volume_iou(g, obj, pts, R_TIP, Z_MIN) == pytest.approx(1.0, abs=1e-12)


def test_a_filled_slot_keeps_the_closure_cell_by_cell():
    """A slot narrower than the finger: the reachable solid fills it; an estimate that fills it too
    scores the same as counted by centres there (the closure is not resolved below a cell)."""
    w = 0.006
    v = np.array([(0, 0), (0.1, 0), (0.1, 0.05 - w), (0.03, 0.05 - w), (0.03, 0.05 + w),
                  (0.1, 0.05 + w), (0.1, 0.1), (0, 0.1)]) - 0.05
    obj = PlacedShape("slot", 2, partial(sdf2d.polygon, vertices=v), np.vstack([v.min(0), v.max(0)]), Pose())
    pts = evaluation_lattice(WS2, 0.002)
    square = np.max(np.abs(pts - (0.5, 0.0)), axis=1) - 0.05  # the slot filled
    pv, centres = (partial_volume_iou(square, obj, pts, R_TIP),
                   reachable_iou(lambda p: square < 0, obj, pts, R_TIP))
    assert pv > 0.99 and pv == pytest.approx(centres, abs=0.01)
    assert partial_volume_iou(square, obj, pts) < 0.97  # against the true solid the slot counts


def test_the_fraction_of_a_cell_under_an_axis_aligned_plane_is_exact():
    pts = evaluation_lattice(WS2, 0.004)
    axes = lattice_axes(pts)
    for offset in (-0.0019, -0.0007, 0.0, 0.0013):
        k = len(pts) // 2
        field = pts[:, 0] - (pts[k, 0] + offset)  # inside where x < the plane
        frac = cell_fraction_below_zero(field, axes, np.array([k]))[0]
        assert frac == pytest.approx(0.5 + offset / 0.004, abs=1e-9)


def test_bad_fields_are_clear_errors():
    obj = make_object("circle")
    pts = evaluation_lattice(WS2, 0.01)
    with pytest.raises(ValueError, match="one value per lattice point"):
        partial_volume_iou(np.zeros(3), obj, pts)
    with pytest.raises(ValueError, match="NaN"):
        partial_volume_iou(np.full(len(pts), np.nan), obj, pts)
