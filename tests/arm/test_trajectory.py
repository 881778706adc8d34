"""Generated trajectories respect position, velocity, acceleration limits and follow the tip path."""

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from tactile_driver.kinematics import ArmModel
from tactile_driver.trajectory import MotionLimits, PathNotFeasible, densify, plan_tip_path, sample_hermite

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
