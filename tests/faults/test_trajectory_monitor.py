"""The trajectory monitor of the motion fault tests can fail: violating trajectories are found.

The oracle for limits is a dense resampling of the executed spline with
finite differences (numpy), not the monitor's exact per-segment extrema.
"""

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from tactile_driver.kinematics import PANDA_JOINTS, ArmModel
from tactile_driver.trajectory import plan_tip_path
from tactile_driver.trajectory_monitor import TrajectoryMonitor

HOME = np.array([0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854])  # tip at (0.50, 0.00, 0.35)
V_MAX, A_MAX = 1.0, 2.0
NAMES = list(PANDA_JOINTS)


@pytest.fixture(scope="module")
def monitor():
    return TrajectoryMonitor.from_params(ArmModel(), [V_MAX] * 7, [A_MAX] * 7, (0.25, 0.75), (-0.30, 0.30),
                                         (0.0, 0.60))


def _fresh(monitor):
    return TrajectoryMonitor(monitor.model, monitor.limits, monitor.box)


def _planned(monitor):
    path = np.array([[0.45, 0.05, 0.25], [0.40, 0.10, 0.06], [0.42, 0.12, 0.06]])
    return plan_tip_path(monitor.model, path, HOME, monitor.limits)


def _dense_extremes(t, q, qd, n=200001):
    """Max |velocity| and |acceleration| per joint by finite differences of the densely sampled spline."""
    ts = np.linspace(t[0], t[-1], n)
    p = CubicHermiteSpline(t, q, qd)(ts)
    v = np.gradient(p, ts, axis=0)
    a = np.gradient(v, ts, axis=0)
    return np.abs(v).max(0), np.abs(a[2:-2]).max(0), p


def test_a_planned_trajectory_passes(monitor):
    traj = _planned(monitor)
    m = _fresh(monitor)
    assert m.check(NAMES, traj.times_s, traj.positions_rad, traj.velocities_rad_s, q_now=HOME) == []
    assert m.checked == 1 and m.violations == []
    # joint order of the message does not matter
    order = [3, 0, 6, 1, 5, 2, 4]
    assert m.check([NAMES[i] for i in order], traj.times_s, traj.positions_rad[:, order],
                   traj.velocities_rad_s[:, order], q_now=HOME) == []


def test_the_same_path_run_faster_breaks_velocity_and_acceleration(monitor):
    traj = _planned(monitor)
    v_planned, _, _ = _dense_extremes(traj.times_s, traj.positions_rad, traj.velocities_rad_s)
    k = 1.5 * V_MAX / v_planned.max()  # the planned path at k times the speed
    assert k > 1.0
    t, q, qd = traj.times_s / k, traj.positions_rad, traj.velocities_rad_s * k
    found = _fresh(monitor).check(NAMES, t, q, qd, q_now=HOME)
    v_ref, a_ref, _ = _dense_extremes(t, q, qd)
    kinds = {v.kind for v in found}
    assert {"velocity", "acceleration"} <= kinds, found
    for v in found:
        j = NAMES.index(v.joint) if v.joint else None
        if v.kind == "velocity":
            assert v.value == pytest.approx(v_ref[j], rel=1e-3) and v_ref[j] > V_MAX
        if v.kind == "acceleration":
            assert v.value == pytest.approx(a_ref[j], rel=2e-2) and a_ref[j] > A_MAX
    # every joint the oracle finds too fast is reported
    assert {NAMES[j] for j in np.flatnonzero(v_ref > V_MAX * 1.001)} <= {v.joint for v in found if v.kind == "velocity"}


def test_an_overshoot_between_knots_beyond_the_joint_limit_is_found(monitor):
    """Both knots inside the limits; the cubic between them goes past joint 4's upper limit."""
    upper = monitor.limits.upper_rad[3]
    q0 = HOME.copy()
    q0[3] = upper - 0.02
    q = np.vstack([q0, q0])
    qd = np.zeros_like(q)
    qd[0, 3], qd[1, 3] = 0.3, -0.3  # out and back: peak 0.3 * h / 4 = 0.075 rad above the knots
    t = np.array([0.0, 1.0])
    _, _, p = _dense_extremes(t, q, qd)
    assert p[:, 3].max() > upper and np.all(q[:, 3] < upper)
    found = _fresh(monitor).check(NAMES, t, q, qd)
    pos = [v for v in found if v.kind == "position"]
    assert len(pos) == 1 and pos[0].joint == "panda_joint4"
    assert pos[0].value == pytest.approx(p[:, 3].max() - upper, abs=1e-6)
    assert pos[0].time_s == pytest.approx(0.5, abs=1e-6)


def test_a_tip_leaving_the_box_is_found(monitor):
    """Joint 1 turned by 1.2 rad swings the tip to y ≈ 0.47 m (box: |y| <= 0.30), slowly enough for the limits."""
    end = HOME.copy()
    end[0] = 1.2
    tip = monitor.model.fk(end)[0]
    assert tip[1] > 0.30
    t = np.linspace(0.0, 6.0, 13)
    s = (3 * (t / 6.0) ** 2 - 2 * (t / 6.0) ** 3)[:, None]  # smooth rest to rest
    sd = (6 * (t / 6.0) - 6 * (t / 6.0) ** 2)[:, None] / 6.0
    q = HOME + s * (end - HOME)
    qd = sd * (end - HOME)
    found = _fresh(monitor).check(NAMES, t, q, qd, q_now=HOME)
    assert [v.kind for v in found] == ["workspace"], found
    # the first sample outside: the oracle's own FK along the spline
    ts = np.linspace(0, 6.0, 6001)
    tips = np.array([monitor.model.fk(qq)[0] for qq in CubicHermiteSpline(t, q, qd)(ts)])
    first = ts[np.argmax(tips[:, 1] > 0.30)]
    assert first - 6.0 / 12 / 9 - 1e-9 <= found[0].time_s <= first + 6.0 / 12 / 9 + 1e-9


def test_a_start_away_from_the_measured_state_is_a_jump(monitor):
    traj = _planned(monitor)
    q_now = HOME.copy()
    q_now[5] += 0.05
    found = _fresh(monitor).check(NAMES, traj.times_s, traj.positions_rad, traj.velocities_rad_s, q_now=q_now)
    assert [(v.kind, v.joint) for v in found] == [("start", "panda_joint6")]
    assert found[0].value == pytest.approx(0.05, abs=1e-9)
    # a first point later than 0: the controller starts from the measured state at rest -> limits from there
    late = _fresh(monitor).check(NAMES, traj.times_s + 0.01, traj.positions_rad, traj.velocities_rad_s,
                                 q_now=q_now)
    assert {v.kind for v in late} >= {"velocity"}


@pytest.mark.parametrize("case", ["names", "nan", "times", "shape", "ragged", "positions_only"])
def test_malformed_trajectories_are_violations(monitor, case):
    traj = _planned(monitor)
    names, t, q, qd = list(NAMES), traj.times_s.copy(), traj.positions_rad.copy(), traj.velocities_rad_s.copy()
    if case == "names":
        names[2] = "elbow"
    elif case == "nan":
        q[3, 1] = np.nan
    elif case == "times":
        t[4] = t[3]
    elif case == "shape":
        qd = qd[:, :6]
    elif case == "ragged":
        q = [list(row) for row in q]
        q[2] = q[2][:6]
    else:
        qd = None
    found = _fresh(monitor).check(names, t, q, qd)
    assert len(found) == 1 and found[0].kind == "malformed", found


def test_a_stop_is_always_safe(monitor):
    m = _fresh(monitor)
    assert m.check(NAMES, [], np.zeros((0, 7))) == []
    assert m.checked == 1


def test_the_box_slack_allows_the_iks_accuracy_and_no_more():
    """The commander lets an IK waypoint lie up to ik_tol_m (0.1 mm) outside the box: a tip held 50 µm
    above the box's top face is a violation for an exact monitor, not for one with that slack; 0.5 mm
    above is one for both."""
    top = ArmModel().fk(HOME)[0][2]
    t, q, qd = np.array([0.0, 1.0]), np.vstack([HOME, HOME]), np.zeros((2, 7))

    def found(over_m, slack_m):
        m = TrajectoryMonitor.from_params(ArmModel(), [V_MAX] * 7, [A_MAX] * 7, (0.25, 0.75), (-0.30, 0.30),
                                          (0.0, top - over_m), box_slack_m=slack_m)
        return [v.kind for v in m.check(NAMES, t, q, qd, q_now=HOME)]

    assert found(5e-5, 0.0) == ["workspace"]
    assert found(5e-5, 1e-4) == []
    assert found(5e-4, 1e-4) == ["workspace"]
    with pytest.raises(ValueError):
        found(0.0, -1e-4)
