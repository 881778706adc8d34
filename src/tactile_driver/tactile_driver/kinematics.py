"""Pinocchio arm model reduced to the arm joints, with a fingertip frame.

Frames: ``world`` = the URDF root (robot base, table top at z = 0). The
fingertip frame has its origin at the centre of the tip and its z-axis from
the tip towards the flange: with the finger vertical (flange pointing down)
the fingertip z-axis is world +z. The tip sits ``tip_offset_m`` along the
flange frame's z-axis (for the Panda, ``panda_link8`` + 0.16 m: a rod finger
mounted on the flange instead of the hand).
"""

from __future__ import annotations

import os
from typing import Optional, Sequence, Tuple

import numpy as np
import pinocchio as pin

#: The Panda's arm joints (the two finger joints are reduced away).
PANDA_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
PANDA_FLANGE = "panda_link8"
PANDA_TIP_OFFSET_M = 0.16
#: Panda home: tip above the workspace, finger vertical (flange down).
PANDA_HOME_RAD = (0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398)


class KinematicsError(ValueError):
    """A model that cannot be built (missing file, unknown joint or frame)."""


def default_urdf_path() -> str:
    """Path of the Franka Panda URDF shipped by example-robot-data."""
    from example_robot_data.robots_loader import getModelPath

    sub = os.path.join("panda_description", "urdf", "panda.urdf")
    return os.path.join(getModelPath(sub), sub)


class ArmModel:
    """Kinematics of the arm joints up to the fingertip frame.

    Args:
        urdf_path: URDF file; '' = the Panda from example-robot-data.
        joint_names: the actuated joints kept, in command order; every other
            joint is locked at its neutral value.
        flange_frame: URDF frame the finger is mounted on.
        tip_offset_m: tip centre along the flange frame's z-axis.
        tip_frame: name of the added fingertip frame.
    """

    def __init__(
        self,
        urdf_path: str = "",
        joint_names: Sequence[str] = PANDA_JOINTS,
        flange_frame: str = PANDA_FLANGE,
        tip_offset_m: float = PANDA_TIP_OFFSET_M,
        tip_frame: str = "fingertip",
    ) -> None:
        path = urdf_path or default_urdf_path()
        if not os.path.isfile(path):
            raise KinematicsError(f"URDF file not found: '{path}'")
        try:
            full = pin.buildModelFromUrdf(path)
        except Exception as exc:  # pinocchio raises its own types
            raise KinematicsError(f"cannot load URDF '{path}': {exc}") from None
        self.full_model = full
        names = list(full.names)
        unknown = [j for j in joint_names if j not in names]
        if unknown:
            raise KinematicsError(f"joint(s) {unknown} not in the URDF; it has {names[1:]}")
        lock = [full.getJointId(n) for n in names[1:] if n not in joint_names]
        model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        if model.nq != len(joint_names) or model.nv != len(joint_names):
            raise KinematicsError("only 1-DoF revolute/prismatic arm joints are supported")
        if not model.existFrame(flange_frame):
            raise KinematicsError(f"flange frame '{flange_frame}' not in the URDF")
        flange_id = model.getFrameId(flange_frame)
        flange = model.frames[flange_id]
        # Tip: offset along the flange z; rotate pi about x so tip z points back to the flange.
        tip_in_flange = pin.SE3(pin.utils.rpyToMatrix(np.pi, 0.0, 0.0), np.array([0.0, 0.0, tip_offset_m]))
        frame = pin.Frame(
            tip_frame, flange.parentJoint, flange_id, flange.placement * tip_in_flange, pin.FrameType.OP_FRAME
        )
        self.tip_frame_id = model.addFrame(frame)
        self.model = model
        self.data = model.createData()
        # Reduced-model joint order follows the URDF tree; map to the requested order.
        self.joint_names = tuple(joint_names)
        model_order = [model.names[i] for i in range(1, model.njoints)]
        self._perm = np.array([model_order.index(j) for j in joint_names])  # user i -> model index
        self.lower_rad = model.lowerPositionLimit[self._perm].copy()
        self.upper_rad = model.upperPositionLimit[self._perm].copy()
        self.velocity_limit_rad_s = model.velocityLimit[self._perm].copy()
        self.urdf_path = path
        self.tip_offset_m = float(tip_offset_m)

    @property
    def nq(self) -> int:
        return len(self.joint_names)

    def _to_model(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise ValueError(f"q must have shape ({self.nq},), got {q.shape}")
        qm = np.empty(self.nq)
        qm[self._perm] = q
        return qm

    def fk(self, q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Tip centre position (3,) and rotation (3, 3), both in the world frame."""
        pin.framesForwardKinematics(self.model, self.data, self._to_model(q))
        m = self.data.oMf[self.tip_frame_id]
        return m.translation.copy(), m.rotation.copy()

    def fk_jacobian(self, q: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tip position, rotation, and the (6, nq) frame Jacobian.

        The Jacobian is LOCAL_WORLD_ALIGNED: rows 0-2 give the tip centre's
        linear velocity in world axes (d p / d q), rows 3-5 the angular
        velocity in world axes, columns in ``joint_names`` order.
        """
        qm = self._to_model(q)
        pin.computeJointJacobians(self.model, self.data, qm)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(self.model, self.data, self.tip_frame_id, pin.LOCAL_WORLD_ALIGNED)
        m = self.data.oMf[self.tip_frame_id]
        return m.translation.copy(), m.rotation.copy(), J[:, self._perm]

    def frame_position(self, q: np.ndarray, frame: str) -> np.ndarray:
        """World position of any frame of the reduced model (e.g. the flange)."""
        pin.framesForwardKinematics(self.model, self.data, self._to_model(q))
        return self.data.oMf[self.model.getFrameId(frame)].translation.copy()

    def within_limits(self, q: np.ndarray, tol_rad: float = 1e-9) -> bool:
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower_rad - tol_rad) and np.all(q <= self.upper_rad + tol_rad))


def home_configuration(model: ArmModel, home_rad: Optional[Sequence[float]] = None) -> np.ndarray:
    """The home joint vector (default: the Panda home, finger vertical), clipped to the limits."""
    q = np.asarray(home_rad if home_rad is not None else PANDA_HOME_RAD, dtype=float)
    if q.shape != (model.nq,):
        raise ValueError(f"home configuration needs {model.nq} values, got {q.shape[0]}")
    return np.clip(q, model.lower_rad, model.upper_rad)
