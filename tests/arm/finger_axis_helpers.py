"""Independent references for the tilted-finger tests: the full Panda model's FK, axes, angles."""

import numpy as np
import pinocchio as pin

from tactile_driver.kinematics import default_urdf_path

OFFSET_M = 0.16  # CommanderConfig.tip_offset_m, ArmModel's default


def full_model():
    """The whole Panda URDF (fingers included) and its data: not the commander's reduced model."""
    model = pin.buildModelFromUrdf(default_urdf_path())
    return model, model.createData()


def full_tip(full, q7):
    """Tip centre and fingertip z-axis from the full model (link8 placement + OFFSET_M along its z)."""
    model, data = full
    q = np.zeros(model.nq)
    q[:7] = q7
    pin.framesForwardKinematics(model, data, q)
    m = data.oMf[model.getFrameId("panda_link8")]
    return m.translation + OFFSET_M * m.rotation[:, 2], -m.rotation[:, 2]


def axis(tilt_deg, azimuth_deg):
    """Unit axis tilted ``tilt_deg`` from world +z towards azimuth ``azimuth_deg`` (from +x towards +y)."""
    t, f = np.radians(tilt_deg), np.radians(azimuth_deg)
    return np.array([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)])


def angle(u, v):
    """Angle between two vectors (rad), from the normalised dot product."""
    c = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.arccos(np.clip(c, -1.0, 1.0)))
