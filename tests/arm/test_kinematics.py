"""Reduced Panda + fingertip frame: FK against the full model, Jacobian against finite differences, IK.

IK to a tilted finger axis is judged on the full model; the vertical default (no axis) against a verbatim copy
of the IK as it was before axes existed (bit for bit: recorded runs depend on it)."""

import warnings

import numpy as np
import pinocchio as pin
import pytest

from tactile_driver.ik import IKSettings, NoSolutionFound, axis_error_rad, solve_ik
from tactile_driver.kinematics import ArmModel, KinematicsError, home_configuration

from finger_axis_helpers import full_model, axis as _axis, angle as _angle

OFFSET_M = 0.16


@pytest.fixture(scope="module")
def arm():
    return ArmModel(tip_offset_m=OFFSET_M)


@pytest.fixture(scope="module")
def full():
    return full_model()


def _random_q(arm, rng, n):
    return rng.uniform(arm.lower_rad, arm.upper_rad, size=(n, arm.nq))


def _full_tip(full, q7):
    """Tip from the full 9-DoF model: link8 placement, then OFFSET_M along its z (independent of ArmModel)."""
    model, data = full
    q = np.zeros(model.nq)
    q[:7] = q7  # panda_joint1..7 come first in the URDF tree; fingers at 0
    pin.framesForwardKinematics(model, data, q)
    m = data.oMf[model.getFrameId("panda_link8")]
    return m.translation + OFFSET_M * m.rotation[:, 2], -m.rotation[:, 2]


def test_reduced_fk_matches_full_panda(arm, full):
    rng = np.random.default_rng(1)
    for q in _random_q(arm, rng, 50):
        p, R = arm.fk(q)
        p_full, z_full = _full_tip(full, q)
        np.testing.assert_allclose(p, p_full, atol=1e-12)
        np.testing.assert_allclose(R[:, 2], z_full, atol=1e-12)  # tip z points back to the flange
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)


def test_home_is_above_workspace_with_finger_vertical(arm):
    p, R = arm.fk(home_configuration(arm))
    assert p[2] > 0.3
    np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=1e-5)


def test_frame_jacobian_against_finite_differences(arm):
    rng = np.random.default_rng(2)
    eps = 1e-6
    for q in _random_q(arm, rng, 20):
        _, R0, J = arm.fk_jacobian(q)
        J_fd = np.zeros((6, arm.nq))
        for j in range(arm.nq):
            dq = np.zeros(arm.nq)
            dq[j] = eps
            p_p, R_p = arm.fk(q + dq)
            p_m, R_m = arm.fk(q - dq)
            J_fd[:3, j] = (p_p - p_m) / (2 * eps)
            # angular velocity in world axes: log(R+ R-ᵀ) / 2 eps
            J_fd[3:, j] = pin.log3(R_p @ R_m.T) / (2 * eps)
        np.testing.assert_allclose(J, J_fd, atol=1e-6)


def test_ik_reaches_random_reachable_positions_within_1mm(arm, full):
    rng = np.random.default_rng(3)
    q0 = home_configuration(arm)
    settings = IKSettings()
    targets = rng.uniform([0.30, -0.25, 0.03], [0.70, 0.25, 0.40], size=(60, 3))
    for target in targets:
        res = solve_ik(arm, target, q0, settings)
        p_full, z_full = _full_tip(full, res.q)
        assert np.linalg.norm(p_full - target) < 1e-3
        assert np.degrees(np.arccos(z_full[2])) < np.degrees(settings.max_tilt_rad) + 1e-6
        assert arm.within_limits(res.q)


def test_ik_unreachable_raises_with_data(arm):
    with pytest.raises(NoSolutionFound, match="position not reached") as info:
        solve_ik(arm, [1.5, 0.0, 0.2], home_configuration(arm))
    assert info.value.residual_m > 0.3
    assert info.value.q_best.shape == (7,)


def test_bad_model_parameters_give_clear_errors():
    with pytest.raises(KinematicsError, match="not found"):
        ArmModel(urdf_path="/nonexistent.urdf")
    with pytest.raises(KinematicsError, match="not in the URDF"):
        ArmModel(joint_names=["panda_joint1", "elbow"])
    with pytest.raises(KinematicsError, match="flange frame"):
        ArmModel(flange_frame="tool0")


HOME = np.array([0.0, -0.1897, 0.0, -2.079, 0.0, 1.8893, 0.7854])  # CommanderConfig.home_rad: tip (0.5, 0, 0.35)


# -- the IK as it was before axes existed (verbatim), the reference of the vertical default ----------------
_EZ_OLD = np.array([0.0, 0.0, 1.0])


class _OldNoSolution(Exception):
    def __init__(self, q_best, residual_m, tilt_rad):
        super().__init__("old IK failed")
        self.q_best, self.residual_m, self.tilt_rad = q_best, residual_m, tilt_rad


def _old_dls(J, damping):
    A = J @ J.T
    A[np.diag_indices_from(A)] += damping**2
    return J.T @ np.linalg.inv(A)


def _old_tilt_of(rotation):
    return float(np.arccos(np.clip(rotation[2, 2], -1.0, 1.0)))


def _old_solve_ik(model, target_xyz, q_init, settings=IKSettings(), q_rest=None):
    s = settings
    target = np.asarray(target_xyz, dtype=float).reshape(3)
    lo = model.lower_rad + s.limit_margin_rad
    hi = model.upper_rad - s.limit_margin_rad
    q = np.clip(np.asarray(q_init, dtype=float), lo, hi)
    rest = q.copy() if q_rest is None else np.asarray(q_rest, dtype=float)
    eye = np.eye(model.nq)
    eye3 = np.eye(3)
    best = (np.inf, q.copy(), np.nan)
    for it in range(1, s.max_iterations + 1):
        p, R, J = model.fk_jacobian(q)
        e_p = target - p
        z = R[:, 2]
        err = float(np.linalg.norm(e_p))
        tilt = _old_tilt_of(R)
        if err < best[0]:
            best = (err, q.copy(), tilt)
        if err <= s.tol_m and tilt <= s.max_tilt_rad:
            return q, err, tilt, it - 1
        Jp = J[:3]
        Jp_pinv = _old_dls(Jp, s.damping)
        dq = Jp_pinv @ (s.gain * e_p)
        N1 = eye - Jp_pinv @ Jp
        Jt = (eye3 - np.outer(z, z)) @ J[3:]
        e_t = s.tilt_gain * np.cross(z, _EZ_OLD)
        JtN = Jt @ N1
        JtN_pinv = _old_dls(JtN, s.damping)
        dq += JtN_pinv @ (e_t - Jt @ dq)
        Ja = np.vstack([Jp, Jt])
        N2 = eye - _old_dls(Ja, s.damping) @ Ja
        dq += N2 @ (s.posture_gain * (rest - q))
        step = float(np.max(np.abs(dq)))
        if step > s.max_step_rad:
            dq *= s.max_step_rad / step
        q = np.clip(q + dq, lo, hi)
    p, R = model.fk(q)
    err, tilt = float(np.linalg.norm(target - p)), _old_tilt_of(R)
    if err < best[0]:
        best = (err, q, tilt)
    raise _OldNoSolution(best[1], best[0], best[2])


# -- vertical default: bit for bit ------------------------------------------------------------------------
@pytest.mark.parametrize("target, settings", [
    ([0.5, 0.0, 0.10], IKSettings()),
    ([0.42, -0.17, 0.03], IKSettings()),
    ([0.66, 0.21, 0.28], IKSettings()),
    ([0.35, 0.05, 0.015], IKSettings(tol_m=1e-6)),
    ([1.5, 0.0, 0.2], IKSettings()),  # unreachable: the failure's best joints too
    ([0.5, 0.0, 0.1], IKSettings(max_tilt_rad=0.0, max_iterations=30)),  # the tilt limit unmet
])
def test_no_axis_is_bit_for_bit_the_vertical_ik_before_axes(arm, target, settings):
    try:
        q_ref, err_ref, tilt_ref, it_ref = _old_solve_ik(arm, target, HOME, settings)
    except _OldNoSolution as ref:
        with pytest.raises(NoSolutionFound) as info:
            solve_ik(arm, target, HOME, settings)
        assert np.array_equal(info.value.q_best, ref.q_best)
        assert info.value.residual_m == ref.residual_m and info.value.tilt_rad == ref.tilt_rad
        assert info.value.axis_xyz is None and "requested finger axis" not in str(info.value)
        return
    res = solve_ik(arm, target, HOME, settings)
    assert np.array_equal(res.q, q_ref)
    assert (res.residual_m, res.tilt_rad, res.iterations) == (err_ref, tilt_ref, it_ref)


# -- IK to a tilted axis ------------------------------------------------------------------------------------
@pytest.mark.parametrize("point, tilt_deg, azimuth_deg", [
    ([0.5, 0.0, 0.10], 30, 0), ([0.5, 0.0, 0.10], 45, 90), ([0.5, 0.0, 0.08], 60, 270),
    ([0.45, 0.1, 0.12], 75, 135), ([0.55, -0.1, 0.15], 90, 45), ([0.5, 0.0, 0.05], 80, 225),
])
def test_ik_puts_the_finger_on_a_tilted_axis(arm, full, point, tilt_deg, azimuth_deg):
    settings = IKSettings()
    axis = _axis(tilt_deg, azimuth_deg)
    res = solve_ik(arm, point, HOME, settings, axis_xyz=3.0 * axis)  # any length: normalised
    tip, z = _full_tip(full, res.q)
    assert np.linalg.norm(tip - point) <= settings.tol_m
    assert _angle(z, axis) <= settings.max_tilt_rad
    assert res.tilt_rad == pytest.approx(_angle(z, axis), abs=1e-7)  # the result reports the axis error
    assert _angle(z, [0.0, 0.0, 1.0]) > np.radians(tilt_deg) - settings.max_tilt_rad - 1e-9  # really tilted
    assert arm.within_limits(res.q)


def test_axis_error_is_the_angle_to_the_axis(arm):
    rng = np.random.default_rng(4)
    for q in rng.uniform(arm.lower_rad, arm.upper_rad, size=(20, arm.nq)):
        R = arm.fk(q)[1]
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        assert axis_error_rad(R, a) == pytest.approx(_angle(R[:, 2], a), abs=1e-7)


def test_a_failed_tilted_ik_reports_the_angle_to_the_requested_axis(arm, full):
    axis = np.array([0.0, 0.0, -1.0])  # flange below the tip: out of reach on the table
    with pytest.raises(NoSolutionFound, match="from the requested finger axis") as info:
        solve_ik(arm, [0.5, 0.0, 0.1], HOME, IKSettings(max_iterations=50), axis_xyz=axis)
    exc = info.value
    np.testing.assert_array_equal(exc.axis_xyz, axis)
    _, z = _full_tip(full, exc.q_best)
    assert exc.tilt_rad == pytest.approx(_angle(z, axis), abs=1e-7)
    assert exc.tilt_rad > 0.1


@pytest.mark.parametrize("bad", [[np.nan, 0.0, 1.0], [0.0, 0.0, 0.0], [np.inf, 0.0, 0.0], [1e-12, 0.0, 0.0],
                                 [1.0, 0.0], "up", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
def test_a_bad_axis_is_a_clear_error_not_a_numpy_traceback(arm, bad):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning from numpy on the way
        with pytest.raises(NoSolutionFound, match="finger axis .* is not a finite non-zero 3-vector") as info:
            solve_ik(arm, [0.5, 0.0, 0.1], HOME, axis_xyz=bad)
    assert info.value.iterations == 0 and info.value.residual_m == np.inf
