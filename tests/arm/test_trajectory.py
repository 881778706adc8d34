"""Generated trajectories respect position, velocity, acceleration limits and follow the tip path.

With finger axes: great-circle interpolation against closed-form angles, rotations in place (no tip travel)
timed by the joint limits, waypoint axes against the full model's FK."""

import warnings

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from tactile_driver.ik import IKSettings, solve_ik
from tactile_driver.kinematics import ArmModel
from tactile_driver.trajectory import (MotionLimits, PathNotFeasible, TrajectoryError, densify, densify_with_axes,
                                       ik_path, plan_tip_path, sample_hermite, slerp_axes, time_parameterize)

from finger_axis_helpers import full_model, full_tip as _full_tip, axis as _axis, angle as _angle

Q_HOME = np.array([0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854])  # tip at (0.5, 0, 0.35)


@pytest.fixture(scope="module")
def arm():
    return ArmModel()


def _lattice_path(rng, n):
    """A random 8-connected lattice walk at z = 0.06 (the planner's kind of path), from above."""
    steps = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1]]) * 0.01
    xy = [np.array([0.40, -0.10])]
    for _ in range(n):
        nxt = xy[-1] + steps[rng.integers(8)]
        xy.append(np.clip(nxt, [0.35, -0.15], [0.65, 0.15]))
    path = np.column_stack([np.array(xy), np.full(len(xy), 0.06)])
    return np.vstack([[0.45, -0.05, 0.25], path])


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_trajectory_respects_limits(arm, seed):
    rng = np.random.default_rng(seed)
    limits = MotionLimits.for_model(arm, rng.uniform(0.5, 1.5), rng.uniform(1.0, 4.0), 0.1)
    path = _lattice_path(rng, 25)
    traj = plan_tip_path(arm, path, Q_HOME, limits)
    assert np.all(np.diff(traj.times_s) > 0)
    np.testing.assert_array_equal(traj.velocities_rad_s[[0, -1]], 0.0)
    # Independent spline (scipy) of what the controller executes, sampled densely.
    spline = CubicHermiteSpline(traj.times_s, traj.positions_rad, traj.velocities_rad_s)
    t = np.linspace(0.0, traj.duration_s, 20000)
    q, qd, qdd = spline(t), spline(t, 1), spline(t, 2)
    assert np.all(q >= limits.lower_rad) and np.all(q <= limits.upper_rad)
    assert np.all(np.abs(qd) <= limits.velocity_rad_s * (1 + 1e-6))
    assert np.all(np.abs(qdd) <= limits.acceleration_rad_s2 * (1 + 1e-6))
    np.testing.assert_allclose(sample_hermite(traj, t)[0], q, atol=1e-12)
    # Waypoints: FK on the requested tip points; the path ends at the goal.
    tips = np.array([arm.fk(x)[0] for x in traj.positions_rad])
    assert np.max(np.linalg.norm(tips[1:] - traj.tip_xyz[1:], axis=1)) < 1e-3
    np.testing.assert_allclose(tips[-1], path[-1], atol=1e-3)
    # Between waypoints the tip stays near the polyline, and near the tip speed.
    tip_dense = np.array([arm.fk(x)[0] for x in q[::50]])
    seg_a, seg_b = traj.tip_xyz[:-1], traj.tip_xyz[1:]
    d = seg_b - seg_a
    u = np.clip(np.einsum("kij,ij->ki", tip_dense[:, None] - seg_a[None], d) / np.maximum((d * d).sum(1), 1e-12), 0, 1)
    dist = np.linalg.norm(tip_dense[:, None] - (seg_a[None] + u[..., None] * d[None]), axis=2).min(axis=1)
    assert dist.max() < 2e-3
    speed = np.linalg.norm(np.diff(tip_dense, axis=0), axis=1) / (t[50] - t[0])
    assert speed.max() < 1.15 * limits.tip_speed_mps


def test_straight_approach_is_fast_and_exact(arm):
    limits = MotionLimits.for_model(arm, 1.0, 2.0, 0.02)
    p0 = arm.fk(Q_HOME)[0]
    traj = plan_tip_path(arm, [p0 + [0, 0, -0.05]], Q_HOME, limits, max_step_m=0.005)
    # rest to rest at 0.02 m/s over 5 cm: at least 2.5 s, and not much slower
    assert 2.5 <= traj.duration_s < 3.5


def test_unreachable_waypoint_is_reported(arm):
    limits = MotionLimits.for_model(arm, 1.0, 2.0, 0.1)
    with pytest.raises(PathNotFeasible, match="waypoint"):
        plan_tip_path(arm, [[0.5, 0.0, 0.3], [1.4, 0.0, 0.3]], Q_HOME, limits)


def test_densify_steps_and_duplicates():
    p = densify(np.array([[0, 0, 0], [0, 0, 1e-5], [0.1, 0, 0], [0.1, 0, 0]]), 0.03)
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert steps.max() <= 0.03 + 1e-12 and steps.min() > 0
    np.testing.assert_array_equal(p[-1], [0.1, 0, 0])
    with pytest.raises(ValueError, match="NaN"):
        densify(np.array([[0, 0, np.nan]]), 0.01)


def test_densify_counts_steps_robustly_at_whole_multiples():
    """A segment a whole number of steps long gives the same waypoints when it is 1e-14 m longer."""
    from tactile_driver.trajectory import densify

    a = densify(np.array([[0.0, 0.0, 0.0], [0.04, 0.0, 0.0]]), 0.005)
    b = densify(np.array([[0.0, 0.0, 0.0], [0.04 + 1e-14, 0.0, 0.0]]), 0.005)
    assert len(a) == len(b) == 9
    assert np.max(np.diff(a[:, 0])) <= 0.005 + 1e-12


# -- finger axes ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def full():
    return full_model()


def test_a_path_without_axes_is_the_vertical_ik_per_waypoint(arm):
    """No axes: exactly densify + solve_ik without an axis (itself bit for bit the old IK, test_kinematics)."""
    limits = MotionLimits.for_model(arm, 1.0, 2.0, 0.1)
    path = np.array([[0.45, -0.05, 0.25], [0.40, -0.10, 0.06], [0.52, 0.03, 0.06], [0.60, 0.12, 0.12]])
    dense = densify(np.vstack([arm.fk(Q_HOME)[0][None], path]), 0.01)
    qs, q = [Q_HOME], Q_HOME
    for target in dense[1:]:
        q = solve_ik(arm, target, q).q
        qs.append(q)
    ref = time_parameterize(np.array(qs), dense, limits)
    traj = plan_tip_path(arm, path, Q_HOME, limits)
    assert np.array_equal(traj.positions_rad, ref.positions_rad)
    assert np.array_equal(traj.times_s, ref.times_s) and np.array_equal(traj.velocities_rad_s, ref.velocities_rad_s)
    assert "axes_xyz" not in traj.meta


def test_bad_axes_of_a_path_are_a_clear_error(arm):
    limits = MotionLimits.for_model(arm, 1.0, 2.0, 0.1)
    for bad, match in [([[np.nan, 0.0, 1.0]], "NaN"), ([[0.0, 0.0, 0.0]], "zero"), ("up", "numbers"),
                       ([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], r"\(1, 3\) array")]:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(TrajectoryError, match=match):
                plan_tip_path(arm, [[0.5, 0.0, 0.1]], Q_HOME, limits, axes_xyz=bad)
    with pytest.raises(TrajectoryError, match=r"\(2, 3\) array, one per path point"):
        ik_path(arm, np.array([[0.5, 0.0, 0.1], [0.5, 0.0, 0.12]]), Q_HOME, axes_xyz=np.array([[0.0, 0.0, 1.0]]))


def test_slerp_against_closed_form_angles():
    rng = np.random.default_rng(5)
    a0 = rng.normal(size=(50, 3))
    a1 = rng.normal(size=(50, 3))
    a0 /= np.linalg.norm(a0, axis=1)[:, None]
    a1 /= np.linalg.norm(a1, axis=1)[:, None]
    t = rng.uniform(0.0, 1.0, 50)
    out = slerp_axes(a0, a1, t)
    theta = np.array([_angle(u, v) for u, v in zip(a0, a1)])
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose([_angle(u, v) for u, v in zip(a0, out)], t * theta, atol=1e-7)
    np.testing.assert_allclose([_angle(u, v) for u, v in zip(out, a1)], (1 - t) * theta, atol=1e-7)
    np.testing.assert_allclose(np.linalg.det(np.stack([a0, a1, out], axis=1)), 0.0, atol=1e-12)  # coplanar
    np.testing.assert_allclose(slerp_axes(a0, a1, np.zeros(50)), a0, atol=1e-12)
    np.testing.assert_allclose(slerp_axes(a0, a1, np.ones(50)), a1, atol=1e-12)


def test_slerp_of_identical_and_opposite_axes():
    a = np.array([[0.0, 0.6, 0.8]])
    np.testing.assert_array_equal(slerp_axes(a, a, np.array([0.3])), a)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        half = slerp_axes(a, -a, np.array([0.5]))[0]
        quarter = slerp_axes(a, -a, np.array([0.25]))[0]
    assert _angle(half, a[0]) == pytest.approx(np.pi / 2, abs=1e-9)
    assert _angle(quarter, a[0]) == pytest.approx(np.pi / 4, abs=1e-9)
    assert abs(np.linalg.det(np.stack([a[0], half, quarter]))) < 1e-12  # one great circle
    np.testing.assert_array_equal(slerp_axes(a, -a, np.array([0.5]))[0], half)  # the same choice every time


def test_densified_axes_follow_the_great_circles_in_small_steps():
    """Moves, a turn in place (the same point twice), an exact duplicate (dropped): closed-form counts and angles."""
    step_m, step_rad = 0.01, 0.05
    p = np.array([[0.5, 0.0, 0.2], [0.5, 0.0, 0.1], [0.5, 0.0, 0.1], [0.5, 0.0, 0.1], [0.53, 0.0, 0.1]])
    a = np.array([[0.0, 0.0, 1.0], _axis(30, 0), _axis(70, 120), _axis(70, 120), _axis(70, 120)])
    out_p, out_a = densify_with_axes(p, a, step_m, step_rad)
    # Segments after dropping the duplicate: 0 -> 1 (10 cm, 30 deg), 1 -> 2 (in place), 2 -> 4 (3 cm, no turn).
    ends = [(0, 1), (1, 2), (2, 4)]
    n = [max(int(np.ceil(np.linalg.norm(p[j] - p[i]) / step_m - 1e-9)),
             int(np.ceil(_angle(a[i], a[j]) / step_rad - 1e-9)), 1) for i, j in ends]
    assert len(out_p) == sum(n) + 1
    np.testing.assert_array_equal(out_p[-1], p[-1])
    np.testing.assert_allclose(out_a[-1], a[-1], atol=1e-15)
    k = 0
    for (i, j), n_seg in zip(ends, n):
        theta = _angle(a[i], a[j])
        for m in range(n_seg):
            np.testing.assert_allclose(out_p[k + m], p[i] + m / n_seg * (p[j] - p[i]), atol=1e-15)
            assert _angle(a[i], out_a[k + m]) == pytest.approx(m / n_seg * theta, abs=1e-7)
            assert _angle(out_a[k + m], a[j]) == pytest.approx((1 - m / n_seg) * theta, abs=1e-7)
        k += n_seg
    steps_m = np.linalg.norm(np.diff(out_p, axis=0), axis=1)
    steps_rad = np.array([_angle(u, v) for u, v in zip(out_a[:-1], out_a[1:])])
    assert steps_m.max() <= step_m + 1e-12 and steps_rad.max() <= step_rad + 1e-9
    assert np.all((steps_m > 0) | (steps_rad > 0))  # the in-place turn kept, the duplicate dropped
    assert int(np.sum(steps_m == 0)) == n[1]


def test_a_path_with_an_axis_turns_from_the_start_axis_and_ends_on_it(arm, full):
    limits = MotionLimits.for_model(arm, 1.0, 2.0, 0.1)
    goal, axis, step_rad = np.array([0.5, 0.1, 0.08]), _axis(60, 135), 0.05
    traj = plan_tip_path(arm, goal[None], Q_HOME, limits, axes_xyz=axis[None], max_step_rad=step_rad)
    axes = traj.meta["axes_xyz"]
    np.testing.assert_allclose(axes[0], _full_tip(full, Q_HOME)[1], atol=1e-12)
    np.testing.assert_allclose(axes[-1], axis, atol=1e-12)
    assert max(_angle(u, v) for u, v in zip(axes[:-1], axes[1:])) <= step_rad + 1e-9
    fk = [_full_tip(full, q) for q in traj.positions_rad]
    assert max(np.linalg.norm(t - x) for (t, _), x in zip(fk[1:], traj.tip_xyz[1:])) <= 1e-4
    assert max(_angle(z, a) for (_, z), a in zip(fk[1:], axes[1:])) <= IKSettings().max_tilt_rad
    assert _angle(fk[-1][1], axis) <= 0.25 * step_rad  # tracked to a quarter step where reachable
    assert np.abs(np.diff(traj.positions_rad, axis=0)).max() <= 0.3


def test_timing_without_tip_travel_even_with_a_repeated_joint_vector(arm):
    """Pure rotation waypoints (the tip fixed), one of them repeated: finite, increasing, within limits."""
    limits = MotionLimits.for_model(arm, 0.8, 1.5, 0.1)
    qs = Q_HOME + np.outer([0.0, 0.05, 0.1, 0.1, 0.2, 0.3], [0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0])
    tip = np.repeat(arm.fk(Q_HOME)[0][None], len(qs), axis=0)
    with np.errstate(all="raise"):
        traj = time_parameterize(qs, tip, limits)
    assert np.all(np.diff(traj.times_s) > 0) and np.all(np.isfinite(traj.velocities_rad_s))
    spline = CubicHermiteSpline(traj.times_s, traj.positions_rad, traj.velocities_rad_s)
    t = np.linspace(0.0, traj.duration_s, 4000)
    assert np.all(np.abs(spline(t, 1)) <= limits.velocity_rad_s * (1 + 1e-6))
    assert np.all(np.abs(spline(t, 2)) <= limits.acceleration_rad_s2 * (1 + 1e-6))
    assert traj.duration_s >= 0.3 / 0.8  # joint 5 turns 0.3 rad at ≤ 0.8 rad/s: the tip speed bounds nothing
