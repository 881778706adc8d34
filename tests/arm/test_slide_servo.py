"""The slide servo core: control law and stop rules against a hand-written contact model."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_driver.slide_servo import ContactSense, ContactThinner, SlideServo, SlideServoConfig, SlideStop

BOX = (np.array([0.0, -1.0, 0.0]), np.array([1.0, 1.0, 1.0]))
R_TIP = 0.01
K_N_PER_M = 2000.0  # a linear spring wall, independent of the sensor model


def wall_contact(tip, x_wall=0.5):
    """Wall x ≥ x_wall, outward normal −x; force k·penetration of the tip's skin (None when free)."""
    pen = tip[0] + R_TIP - x_wall
    if pen <= 0:
        return None
    return ContactSense(np.array([x_wall, tip[1], tip[2]]), np.array([-1.0, 0.0, 0.0]), K_N_PER_M * pen)


def run(servo, tip, contact_fn, n=100000):
    tips, forces = [tip.copy()], []
    for _ in range(n):
        c = contact_fn(tip)
        forces.append(0.0 if c is None else c.force_n)
        step = servo.step(tip, c)
        if step.target_xyz is not None:
            tip = step.target_xyz
            tips.append(tip.copy())
        if step.stop is not None:
            return step.stop, np.array(tips), np.array(forces)
    raise AssertionError("servo never stopped")


def test_servo_regulates_the_force_and_slides_the_planned_length():
    cfg = SlideServoConfig(gain_m_per_n=1.0 / K_N_PER_M * 0.5)
    tip = np.array([0.5 - R_TIP + 0.00002, 0.0, 0.06])  # just touching (0.04 N)
    servo = SlideServo(cfg, np.array([1.0, 1.0, 0.0]), 0.05, *BOX, planar=True)  # not tangent: projected
    stop, tips, forces = run(servo, tip, wall_contact)
    assert stop is SlideStop.LENGTH
    assert servo.slid_m == pytest.approx(0.05)
    assert tips[-1, 1] - tips[0, 1] == pytest.approx(0.05, abs=1e-9)  # all of it along the tangent +y
    assert np.allclose(tips[:, 2], 0.06)
    # P control on a linear spring: the error halves each tick; in the band after a few ticks
    assert forces[10:].min() == pytest.approx(cfg.target_force_n, rel=1e-3)
    # each tick advances one step (after the weak ticks of the press-in)
    weak = int(np.sum(forces < cfg.min_force_n))
    assert servo.ticks == pytest.approx(0.05 / cfg.step_m + weak, abs=1)
    assert servo.duration_s == pytest.approx(servo.ticks / cfg.control_rate_hz)


def test_tangent_follows_the_sensed_normal():
    cfg = SlideServoConfig()
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 1.0, *BOX, planar=True)
    tip = np.zeros(3) + 0.5
    n = np.array([np.cos(0.3), np.sin(0.3), 0.0])
    step = servo.step(tip, ContactSense(tip - R_TIP * n, n, cfg.target_force_n))
    t = (step.target_xyz - tip) / cfg.step_m
    assert t @ n == pytest.approx(0.0, abs=1e-12) and t[1] > 0 and np.linalg.norm(t) == pytest.approx(1.0)


def test_lost_contact_searches_along_the_last_normal_then_stops():
    cfg = SlideServoConfig(lost_ticks=5)
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 1.0, *BOX, planar=True)
    tip = np.array([0.49, 0.0, 0.06])
    n = np.array([-1.0, 0.0, 0.0])
    tip = servo.step(tip, ContactSense(tip - R_TIP * n, n, cfg.target_force_n)).target_xyz
    targets = []
    for _ in range(10):
        s = servo.step(tip, None)
        if s.stop is not None:
            break
        targets.append(s.target_xyz)
        tip = s.target_xyz
    assert s.stop is SlideStop.LOST and s.target_xyz is None and len(targets) == cfg.lost_ticks - 1
    moves = np.diff(np.array(targets), axis=0)
    assert np.allclose(moves, [cfg.max_correction_m, 0, 0])  # into the surface, no tangent step
    assert servo.step(tip, None).stop is SlideStop.LOST  # stays stopped


def test_a_weak_contact_is_pressed_in_at_the_full_correction_rate():
    """A contact below the band (a grazing touch: a round tip's spring force grows with the square of
    its depth, F = c·δ², so the proportional correction is tiny there) is pressed in by
    max_correction_m per tick, without a tangent step, until the force is back in the band."""
    cfg = SlideServoConfig()
    c_n_per_m2 = 6.3e5  # a 1 cm sphere on the 2e7 Pa/m skin: F = k·π·r·δ²
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.01, *BOX, planar=True)

    def hertz_wall(tip, x_wall=0.5):
        pen = tip[0] + R_TIP - x_wall
        return None if pen <= 0 else ContactSense(np.array([x_wall, tip[1], tip[2]]), np.array([-1.0, 0.0, 0.0]),
                                                   c_n_per_m2 * pen**2)

    tip = np.array([0.5 - R_TIP + 0.00001, 0.0, 0.06])  # 10 µm deep: 6e-5 N
    stop, tips, forces = run(servo, tip, hertz_wall)
    assert stop is SlideStop.LENGTH
    weak = int(np.sum(forces < cfg.min_force_n))
    depth_min_m = np.sqrt(cfg.min_force_n / c_n_per_m2)  # 0.31 mm
    # one tick (the proportional law took 12)
    assert weak == int(np.ceil((depth_min_m - 0.00001) / cfg.max_correction_m))
    assert np.allclose(np.diff(tips[:weak + 1], axis=0), [cfg.max_correction_m, 0.0, 0.0])  # in, no step
    assert forces[weak:].max() < cfg.max_force_n


def test_a_slide_whose_contacts_have_no_normal_servos_on_the_given_one():
    """Contacts on the finger's rim carry no normal (NaN): with the approach's normal given, the servo
    slides the wall with it (the same path as with sensed normals); without, it ends at once."""
    cfg = SlideServoConfig(gain_m_per_n=1.0 / K_N_PER_M * 0.5)
    tip = np.array([0.5 - R_TIP + 0.00002, 0.0, 0.06])

    def rim(t):
        c = wall_contact(t)
        return None if c is None else ContactSense(c.point_xyz, np.full(3, np.nan), c.force_n)

    no_normal = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.05, *BOX)
    assert run(no_normal, tip, rim)[0] is SlideStop.LOST and no_normal.slid_m == 0.0
    given = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.05, *BOX, normal_xyz=np.array([-1.0, 0.0, 0.0]))
    stop, tips, forces = run(given, tip, rim)
    sensed = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.05, *BOX)
    _, tips_sensed, _ = run(sensed, tip, wall_contact)
    assert stop is SlideStop.LENGTH and given.slid_m == pytest.approx(0.05)
    np.testing.assert_allclose(tips, tips_sensed, atol=1e-12)
    # a sensed normal replaces the given one
    turned = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.05, *BOX, normal_xyz=np.array([0.0, 0.0, 1.0]))
    turned.step(tip, wall_contact(tip))
    np.testing.assert_allclose(turned.normal, [-1.0, 0.0, 0.0])


def test_force_above_the_band_stops_at_once():
    cfg = SlideServoConfig()
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 1.0, *BOX)
    n = np.array([-1.0, 0.0, 0.0])
    s = servo.step(np.full(3, 0.5), ContactSense(np.full(3, 0.5), n, cfg.max_force_n * 1.01))
    assert s.stop is SlideStop.FORCE and s.target_xyz is None


def test_box_stops_before_leaving_it():
    cfg = SlideServoConfig(gain_m_per_n=1.0 / K_N_PER_M * 0.5)
    box = (np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.02, 1.0]))
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 1.0, *box, planar=True)
    stop, tips, _ = run(servo, np.array([0.5 - R_TIP + 0.0002, 0.0, 0.06]), wall_contact)
    assert stop is SlideStop.BOX and tips[:, 1].max() <= 0.02 and tips[-1, 1] > 0.02 - cfg.step_m


@pytest.mark.parametrize("direction, goes_on", [((0.0, 1.0, -0.5), True), ((0.0, 0.3, -1.0), False)])
def test_a_3d_slide_at_the_floor_goes_on_along_it_unless_it_heads_down(direction, goes_on):
    """3D, a wall down to the table: a slide heading along and down reaches the box's floor and goes on
    along it, at the floor, to its planned length (the foot of the wall); one heading down more steeply
    than FLOOR_MIN_TXY allows ends there on the box. No target is ever below the floor."""
    cfg = SlideServoConfig(gain_m_per_n=1.0 / K_N_PER_M * 0.5)
    floor = 0.05
    box = (np.array([0.0, -1.0, floor]), np.array([1.0, 1.0, 1.0]))
    servo = SlideServo(cfg, np.array(direction), 0.06, *box)
    stop, tips, _ = run(servo, np.array([0.5 - R_TIP + 0.00002, 0.0, 0.06]), wall_contact)
    assert tips[:, 2].min() >= floor - 1e-12
    if goes_on:
        assert stop is SlideStop.LENGTH and servo.slid_m == pytest.approx(0.06)
        assert tips[-1, 2] < floor + cfg.step_m
        # down to the floor along the wall (1 cm at t_z = -1/sqrt(5)), then along the floor
        assert tips[-1, 1] == pytest.approx(0.01 * 2.0 + (0.06 - 0.01 * np.sqrt(5.0)), abs=cfg.step_m)
    else:
        assert stop is SlideStop.BOX and tips[-1, 2] < floor + cfg.step_m


def test_lap_closes_when_the_contact_returns_to_its_start():
    cfg = SlideServoConfig()
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 10.0, *BOX, planar=True)
    n = np.array([-1.0, 0.0, 0.0])
    # the contact moves one step per tick for 30 mm, then is back 2 mm from where it began
    seq = [np.array([0.5, y, 0.06]) for y in np.arange(0, 0.03, cfg.step_m)] + [np.array([0.5, 0.002, 0.06])]
    stops = [servo.step(p + R_TIP * n, ContactSense(p, n, cfg.target_force_n)).stop for p in seq]
    assert stops[:-1] == [None] * (len(seq) - 1) and stops[-1] is SlideStop.LAP


def corner_contact(tip):
    """The solid quarter x ≥ 0.5, y ≤ 0 (a sharp convex edge along z at (0.5, 0)): contact at the
    solid's nearest point, normal from it to the tip, force k·penetration of the tip's skin."""
    near = np.array([max(tip[0], 0.5), min(tip[1], 0.0), tip[2]])
    d = float(np.linalg.norm(tip - near))
    if d >= R_TIP or d == 0.0:
        return None
    return ContactSense(near, (tip - near) / d, K_N_PER_M * (R_TIP - d))


def test_rolling_round_a_sharp_corner_near_the_start_is_not_a_lap():
    """A slide that starts 3 mm before a sharp convex edge: the contact stays on the edge while the
    tip rolls a quarter circle round it (1.6 cm), so the contact is within lap_radius_m of the first
    one after 4 lap radii of slide, but the tip is not back: the slide goes on round the corner and
    along the next face to its planned length."""
    cfg = SlideServoConfig(gain_m_per_n=1.0 / K_N_PER_M * 0.5)
    tip = np.array([0.5 - R_TIP + 0.00002, -0.003, 0.06])
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.05, *BOX, planar=True)
    stop, tips, _ = run(servo, tip, corner_contact)
    assert stop is SlideStop.LENGTH
    assert tips[-1, 1] == pytest.approx(R_TIP, abs=1e-3)  # on the face y = 0, a tip radius off it
    assert tips[-1, 0] > 0.5 + 0.015  # and well along it


def test_a_slide_that_settles_below_its_first_contact_ends_after_one_lap_there():
    """A 3D slide on a vertical cylinder (radius R) whose first contact is 10 mm above the height it
    settles at, then circles there: the first-contact rule never fires (the circle stays 10 mm below
    it); the tip comes back to where it was one circumference before, and the slide ends there."""
    cfg = SlideServoConfig()
    R, z0, z1, drop_m = 0.03, 0.074, 0.064, 0.01
    servo = SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.6, *BOX)
    h = cfg.step_m
    for _ in range(2000):  # the tip is scripted: down first, then round the circle at z1 (arc length = slid)
        s_m = servo.slid_m
        if s_m < drop_m:
            tip = np.array([0.5 + R + R_TIP, 0.0, z0 - s_m])
            a = 0.0
        else:
            a = (s_m - drop_m) / (R + R_TIP)
            tip = np.array([0.5 + (R + R_TIP) * np.cos(a), (R + R_TIP) * np.sin(a), z1])
        n = np.array([np.cos(a), np.sin(a), 0.0])
        step = servo.step(tip, ContactSense(tip - R_TIP * n, n, cfg.target_force_n))
        if step.stop is not None:
            break
    assert step.stop is SlideStop.LAP
    lap_m = 2.0 * np.pi * (R + R_TIP)  # the tip's circle
    assert drop_m + lap_m - cfg.lap_radius_m - h < servo.slid_m < drop_m + lap_m


def test_thinner_keeps_contacts_by_distance_and_turn():
    th = ContactThinner(0.0049, np.radians(10))
    n0 = np.array([-1.0, 0, 0])
    kept = [th.offer(ContactSense(np.array([0.5, y, 0]), n0, 0.5)) for y in np.arange(0, 0.0201, 0.001)]
    assert np.nonzero(kept)[0].tolist() == [0, 5, 10, 15, 20]
    a = np.radians(11)
    assert th.offer(ContactSense(np.array([0.5, 0.0201, 0]), np.array([-np.cos(a), np.sin(a), 0]), 0.5))
    assert not th.offer(ContactSense(np.full(3, np.nan), n0, 0.5))


@pytest.mark.parametrize("kw, match", [
    (dict(slide_speed_mps=0.0), "slide_speed_mps"),
    (dict(min_force_n=0.6, target_force_n=0.5), "force band"),
    (dict(max_force_n=0.1), "force band"),
    (dict(lost_ticks=0), "lost_ticks"),
])
def test_bad_config_is_refused_with_its_name(kw, match):
    with pytest.raises(ValueError, match=match):
        SlideServoConfig(**kw).validate()


def test_bad_slide_is_refused():
    cfg = SlideServoConfig()
    with pytest.raises(ValueError, match="direction"):
        SlideServo(cfg, np.array([0.0, 0.0, 1.0]), 0.1, *BOX, planar=True)
    with pytest.raises(ValueError, match="length"):
        SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.0, *BOX)
    with pytest.raises(ValueError, match="box"):
        SlideServo(cfg, np.array([0.0, 1.0, 0.0]), 0.1, BOX[1], BOX[0])


def test_from_params_reads_the_prefixed_names():
    cfg = SlideServoConfig.from_params({"slide.target_force_n": 0.8, "slide.lost_ticks": 7, "other": 1}, "slide.")
    assert cfg.target_force_n == 0.8 and cfg.lost_ticks == 7 and isinstance(cfg.lost_ticks, int)
