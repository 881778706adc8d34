"""Reduced Panda + fingertip frame: FK against the full model, Jacobian against finite differences, IK."""

import numpy as np
import pinocchio as pin
import pytest

from tactile_driver.ik import IKSettings, NoSolutionFound, solve_ik
from tactile_driver.kinematics import ArmModel, KinematicsError, default_urdf_path, home_configuration

OFFSET_M = 0.16


@pytest.fixture(scope="module")
def arm():
    return ArmModel(tip_offset_m=OFFSET_M)


@pytest.fixture(scope="module")
def full():
    model = pin.buildModelFromUrdf(default_urdf_path())
    return model, model.createData()


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
