"""Contact location, normal and force against analytic planes, cylinders and spheres.

The fingertip approaches the object through the sensor model, the protocol
encoder/decoder and the contact detector (``simulate_approach`` with
``through_protocol=True``); the estimate is compared with the closest point
of the analytic object to the tip centre where the approach stopped.
"""

import numpy as np
import pytest
from sensor_shapes import Cylinder, Plane, Sphere, rotation_about

from tactile_driver.contact import ContactConfig, ContactDetector, back_off_target
from tactile_driver.taxels import hemisphere_layout, ring_layout
from tactile_sim.sensor_model import SensorModel
from tactile_sim.touch import simulate_approach

TIP0 = np.array([0.50, 0.0, 0.06])
STEP_M = 0.0001  # 2 cm/s at 200 Hz


class TiltedCylinder:
    """Infinite cylinder of radius r around an axis through c with unit direction a."""

    def __init__(self, c, a, r):
        self.dim, self.c, self.a, self.r = 3, np.asarray(c, float), np.asarray(a, float) / np.linalg.norm(a), r

    def _radial(self, p):
        d = np.atleast_2d(p) - self.c
        return d - np.outer(d @ self.a, self.a)

    def sdf(self, p):
        return np.linalg.norm(self._radial(p), axis=1) - self.r

    def gradient(self, p):
        d = self._radial(p)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def closest_point(self, x):
        d = self._radial(x)[0]
        return x - d + self.r * d / np.linalg.norm(d)


def errors(obj, res):
    truth = obj.closest_point(res.tip_xyz_at_stop)
    if truth.shape[0] == 2:  # 2D object: the contact is at the tip's height
        truth = np.r_[truth, res.tip_xyz_at_stop[2]]
    g = obj.gradient(truth[None, : obj.dim])[0]
    g = np.r_[g, 0.0] if g.shape[0] == 2 else g
    err_m = np.linalg.norm(res.point_xyz - truth)
    ang = np.degrees(np.arccos(np.clip(res.normal_xyz @ g, -1.0, 1.0)))
    return err_m, ang


def approach(obj, layout, model, d, R=np.eye(3), seed=0):
    det = ContactDetector(layout, ContactConfig())
    res = simulate_approach(obj, layout, model, det, TIP0, d, 0.02, STEP_M, R,
                            np.random.default_rng(seed), through_protocol=True)
    assert res.contact, "the approach must end in a contact"
    return res


@pytest.mark.parametrize("dim", [2, 3])
def test_ring_finger_against_vertical_plane_and_cylinder(dim):
    layout = ring_layout()
    model = SensorModel(layout, seed=1)
    rng = np.random.default_rng(10 + dim)
    worst = [0.0, 0.0]
    for k in range(12):
        ang = rng.uniform(0, 2 * np.pi)
        d = np.array([np.cos(ang), np.sin(ang), 0.0])
        if k % 2 == 0:
            obj = Plane(TIP0 + 0.012 * d, -d, dim=dim)
        else:
            obj = Cylinder(TIP0[:2] + 0.05 * d[:2], 0.035, dim=dim)
        res = approach(obj, layout, model, d, seed=k)
        err_m, ang_deg = errors(obj, res)
        worst = [max(worst[0], err_m), max(worst[1], ang_deg)]
        assert res.travel_m == pytest.approx(0.002 if k % 2 == 0 else 0.005, abs=0.0008)
    assert worst[0] < 0.001 and worst[1] < 5.0, f"worst error {worst[0]*1e3:.2f} mm, {worst[1]:.2f} deg"


def test_hemisphere_finger_against_plane_cylinder_sphere_at_tilted_poses():
    layout = hemisphere_layout()
    model = SensorModel(layout, seed=2)
    rng = np.random.default_rng(5)
    worst = [0.0, 0.0]
    for k in range(18):
        # approach directions from straight down to 25 deg below horizontal: contact on the cap
        az, el = rng.uniform(0, 2 * np.pi), rng.uniform(-np.pi / 2, -np.radians(25))
        d = np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        R = rotation_about(rng.normal(size=3), rng.uniform(0.0, 0.3))
        if k % 3 == 0:
            obj = Plane(TIP0 + 0.015 * d, -d)
        elif k % 3 == 1:
            axis = np.cross(d, [0.0, 0.0, 1.0])
            obj = TiltedCylinder(TIP0 + 0.045 * d, axis, 0.03)
        else:
            obj = Sphere(TIP0 + 0.045 * d, 0.03)
        res = approach(obj, layout, model, d, R, seed=k)
        err_m, ang_deg = errors(obj, res)
        worst = [max(worst[0], err_m), max(worst[1], ang_deg)]
    assert worst[0] < 0.001 and worst[1] < 5.0, f"worst error {worst[0]*1e3:.2f} mm, {worst[1]:.2f} deg"


def test_force_estimate_tracks_the_spring_force():
    layout = hemisphere_layout()
    model = SensorModel(layout, seed=3)
    obj = Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    det = ContactDetector(layout, ContactConfig())
    rng = np.random.default_rng(0)
    for _ in range(det.config.calibration_frames):
        det.update(model.frame(obj, [0.5, 0.0, 0.05], np.eye(3), rng))
    for depth_m in (0.0003, 0.0006, 0.001):
        tip = np.array([0.5, 0.0, 0.010 - depth_m])
        det.update(model.frame(obj, tip, np.eye(3), rng))
        # independent: spring pressure k*delta over the cap, integral of k (delta - r(1 - cos phi)) dA
        r, k = 0.010, model.config.stiffness_pa_per_m
        expected = k * np.pi * depth_m**2 * r  # paraboloid cap volume, small depth
        assert det.force_n == pytest.approx(expected, rel=0.15)


def test_approach_in_free_space_reports_no_contact():
    layout = ring_layout()
    model = SensorModel(layout, seed=1)
    obj = Plane([0.6, 0.0, 0.0], [-1.0, 0.0, 0.0], dim=2)
    det = ContactDetector(layout, ContactConfig())
    res = simulate_approach(obj, layout, model, det, TIP0, [-1.0, 0.0, 0.0], 0.03, STEP_M,
                            rng=np.random.default_rng(0))
    assert not res.contact and res.travel_m == 0.03
    np.testing.assert_allclose(res.tip_xyz_at_stop, TIP0 - [0.03, 0.0, 0.0])


def test_ring_contacts_carry_the_tip_height_exactly():
    layout = ring_layout()
    model = SensorModel(layout, seed=4)
    d = np.array([0.0, 1.0, 0.0])
    res = approach(Cylinder(TIP0[:2] + 0.05 * d[:2], 0.035, dim=2), layout, model, d, seed=1)
    assert res.point_xyz[2] == TIP0[2]


def test_hemisphere_side_contacts_keep_the_normal_only_below_the_rim():
    """A horizontal approach: a vertical wall presses mid-band (normal kept, < 5 deg); a ball
    met below its equator presses the band's upper rim, where the finger's horizontal normal
    is up to 35 deg off the ball's: the point is kept (< 1.5 mm), the normal is reported unknown."""
    layout = hemisphere_layout()
    model = SensorModel(layout, seed=6)
    d = np.array([1.0, 0.0, 0.0])
    wall = Plane(TIP0 + 0.015 * d, -d)
    res = approach(wall, layout, model, d)
    assert abs(wall.sdf(res.point_xyz[None])[0]) < 0.001  # on the wall (at any height of the band)
    assert np.degrees(np.arccos(res.normal_xyz @ -d)) < 5.0
    for below_m in (0.015, 0.03):  # ball centre this far above the tip centre
        ball = Sphere(TIP0 + [0.065, 0.0, below_m], 0.05)
        res = approach(ball, layout, model, d, seed=1)
        assert np.all(np.isnan(res.normal_xyz)), res.normal_xyz
        assert abs(ball.sdf(res.point_xyz[None])[0]) < 0.0015
        true_n = ball.gradient(res.point_xyz[None])[0]
        assert np.degrees(np.arccos(true_n @ d * -1.0)) > 10.0  # the finger's normal would be this far off


def test_back_off_target_leaves_along_tip_minus_contact():
    contact, tip = np.array([0.5, 0.0, 0.06]), np.array([0.5, 0.003, 0.064])  # 5 mm, a 3-4-5 direction
    np.testing.assert_allclose(back_off_target(contact, tip, 0.02), [0.5, 0.012, 0.076])
    assert back_off_target(contact, contact, 0.02) is None  # no direction
    assert back_off_target(np.full(3, np.nan), tip, 0.02) is None
