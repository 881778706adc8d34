"""The simulated slide: the driver's detector and the slide servo, frame by frame, on analytic shapes.

Ground truth is written here (disc, square, circular cavity), not taken from tactile_sim.objects.
"""

from __future__ import annotations

import numpy as np
import pytest

from tactile_driver.contact import ContactConfig, ContactDetector
from tactile_driver.slide_servo import ContactThinner, SlideServo, SlideServoConfig, SlideStop
from tactile_driver.taxels import load_layout
from tactile_common.params_file import package_config
from tactile_sim.sensor_model import SensorModel
from tactile_sim.slide import simulate_slide
from tactile_sim.touch import simulate_approach

Z = 0.06
BOX = (np.array([0.25, -0.3, 0.0]), np.array([0.75, 0.3, 0.6]))


class Disc:
    dim = 2

    def __init__(self, c, r):
        self.c, self.r = np.asarray(c, float), float(r)

    def sdf(self, p):
        return np.linalg.norm(np.asarray(p)[:, :2] - self.c, axis=1) - self.r


class Cavity:
    """Solid everywhere except a circular hole of radius r: the finger inside slides on a concave arc."""

    dim = 2

    def __init__(self, c, r):
        self.c, self.r = np.asarray(c, float), float(r)

    def sdf(self, p):
        return self.r - np.linalg.norm(np.asarray(p)[:, :2] - self.c, axis=1)


class Square:
    """Axis-aligned square of half side h (exact box SDF)."""

    dim = 2

    def __init__(self, c, h):
        self.c, self.h = np.asarray(c, float), float(h)

    def sdf(self, p):
        q = np.abs(np.asarray(p)[:, :2] - self.c) - self.h
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


@pytest.fixture(scope="module")
def layout():
    return load_layout(package_config("tactile_driver", "taxels_ring.yaml"))


def slide_on(obj, layout, start, approach_dir, slide_dir, length_m, cfg=SlideServoConfig(), box=BOX, seed=0):
    model = SensorModel(layout, seed=seed)
    det = ContactDetector(layout, ContactConfig())
    rng = np.random.default_rng(seed)
    app = simulate_approach(obj, layout, model, det, np.array(start, float), np.array(approach_dir, float),
                            0.05, 0.0001, rng=rng)
    assert app.contact
    servo = SlideServo(cfg, np.array(slide_dir, float), length_m, box[0], box[1], planar=True)
    res = simulate_slide(obj, model, det, servo, ContactThinner(cfg.thin_distance_m, cfg.thin_angle_rad),
                         app.tip_xyz_at_stop, rng=rng)
    return app, res


def in_band_after_press(res, cfg):
    f = res.forces_all_n
    k = int(np.argmax(f >= cfg.target_force_n * 0.9))  # the press-in after the approach's onset
    return f[k:], k


def test_slide_keeps_contact_on_a_circle_within_the_band(layout):
    obj, cfg = Disc([0.5, 0.0], 0.04), SlideServoConfig()
    app, res = slide_on(obj, layout, [0.43, 0.0, Z], [1, 0, 0], [0, -1, 0], 0.2)
    assert res.stop is SlideStop.LENGTH and res.slid_m == pytest.approx(0.2)
    f, k = in_band_after_press(res, cfg)
    assert k < 20 and f.min() >= cfg.min_force_n and f.max() <= cfg.max_force_n
    # the tip centre stays at the finger's radius minus a fraction of a millimetre of skin compression
    gap = obj.sdf(res.tip_path_xyz) - layout.tip_radius_m
    assert gap.max() < 0.0 and gap.min() > -0.001
    # the contacts lie on the circle, with its normals, every ~5 mm, going clockwise (−y first at x < c)
    assert np.abs(obj.sdf(res.points_xyz)).max() < 0.001
    true_n = (res.points_xyz[:, :2] - obj.c) / np.linalg.norm(res.points_xyz[:, :2] - obj.c, axis=1)[:, None]
    assert np.einsum("ij,ij->i", true_n, res.normals_xyz[:, :2]).min() > np.cos(np.radians(3))
    assert 0.2 / 0.005 * 0.7 < res.n_contacts < 0.2 / 0.005 * 1.3 + 2
    ang = np.unwrap(np.arctan2(res.points_xyz[:, 1], res.points_xyz[:, 0] - 0.5))
    assert ang[-1] - ang[0] > 0.2 / (0.04 + 0.01) * 0.8  # it went round, about slide / (r + tip r) rad


def test_slide_wraps_the_corners_of_a_square(layout):
    obj, cfg = Square([0.5, 0.0], 0.03), SlideServoConfig()
    app, res = slide_on(obj, layout, [0.44, 0.01, Z], [1, 0, 0], [0, 1, 0], 0.3)
    assert res.stop in (SlideStop.LENGTH, SlideStop.LAP)
    f, _ = in_band_after_press(res, cfg)
    assert f.max() <= cfg.max_force_n
    gap = obj.sdf(res.tip_path_xyz) - layout.tip_radius_m
    # never far, never deep: on a vertex the contact area is small, so the band's force sits deeper
    assert gap.min() > -0.0025 and gap.max() < 0.0015
    assert np.abs(obj.sdf(res.points_xyz)).max() < 0.0015
    # all four sides were sensed: contacts near x = ±h and y = ±h
    p = res.points_xyz[:, :2] - obj.c
    for side in (p[:, 0] < -0.029, p[:, 0] > 0.029, p[:, 1] < -0.029, p[:, 1] > 0.029):
        assert side.sum() >= 3


def test_slide_follows_a_concave_arc_within_the_band(layout):
    obj, cfg = Cavity([0.5, 0.0], 0.05), SlideServoConfig()
    app, res = slide_on(obj, layout, [0.5, 0.0, Z], [-1, 0, 0], [0, 1, 0], 0.15)
    assert res.stop is SlideStop.LENGTH
    f, k = in_band_after_press(res, cfg)
    assert k < 20 and f.min() >= cfg.min_force_n and f.max() <= cfg.max_force_n
    r = np.linalg.norm(res.points_xyz[:, :2] - obj.c, axis=1)
    assert np.abs(r - 0.05).max() < 0.001


def test_slide_stops_at_the_box(layout):
    obj = Square([0.5, 0.0], 0.2)  # a long wall at x = 0.3
    box = (np.array([0.25, -0.05, 0.0]), np.array([0.75, 0.05, 0.6]))
    app, res = slide_on(obj, layout, [0.27, 0.0, Z], [1, 0, 0], [0, 1, 0], 0.3, box=box)
    assert res.stop is SlideStop.BOX
    assert np.all(res.tip_path_xyz[:, 1] <= 0.05) and res.tip_path_xyz[-1, 1] > 0.05 - 0.001
    assert res.slid_m == pytest.approx(res.tip_path_xyz[-1, 1] - app.tip_xyz_at_stop[1], abs=0.001)


class EndingWall:
    """Material at x ≥ 0.46 for y < y_end only: the surface ends at y_end with nothing to wrap
    around (as a wall's top edge ends under a finger sliding up it)."""

    dim = 2

    def __init__(self, y_end):
        self.y_end = float(y_end)

    def sdf(self, p):
        p = np.asarray(p)[:, :2]
        return np.where(p[:, 1] < self.y_end, 0.46 - p[:, 0], 1.0)


def test_slide_stops_cleanly_where_the_surface_ends(layout):
    obj, cfg = EndingWall(0.03), SlideServoConfig()
    app, res = slide_on(obj, layout, [0.43, 0.0, Z], [1, 0, 0], [0, 1, 0], 0.2, cfg=cfg)
    # it ends there: the contact fades (lost) or the finger, turning round the end, presses on the
    # wall's end face beyond the band (force); either way within a tick of leaving the band
    assert res.stop in (SlideStop.LOST, SlideStop.FORCE)
    assert res.forces_all_n[:-1].max() <= cfg.max_force_n
    end = res.points_xyz[-1]
    # at the wall's end: on a knife-sharp vertex the pressure centroid (the detector's contact) sinks
    # millimetres into the finger, so the point is good to under a tip radius (8 mm) there
    assert np.linalg.norm(end[:2] - [0.46, 0.03]) < 0.008 and end[1] <= 0.03
    assert np.all(res.points_xyz[:, 1] <= 0.03)
    assert res.slid_m < 0.03 + 0.01


def test_slide_stops_when_the_force_leaves_the_band(layout):
    """A wall much stiffer than the servo's gain assumes: the first correction overshoots the band's top."""
    obj = Disc([0.5, 0.0], 0.04)
    cfg = SlideServoConfig(gain_m_per_n=5e-3, max_correction_m=0.003, max_force_n=1.0)
    app, res = slide_on(obj, layout, [0.43, 0.0, Z], [1, 0, 0], [0, -1, 0], 0.2, cfg=cfg)
    assert res.stop is SlideStop.FORCE and res.slid_m < 0.01


def test_simulated_slide_refuses_an_uncalibrated_detector(layout):
    model = SensorModel(layout)
    servo = SlideServo(SlideServoConfig(), np.array([0, 1.0, 0]), 0.1, *BOX, planar=True)
    with pytest.raises(ValueError, match="calibrated"):
        simulate_slide(Disc([0.5, 0], 0.04), model, ContactDetector(layout), servo, ContactThinner(0.005, 0.2),
                       np.array([0.45, 0, Z]))
