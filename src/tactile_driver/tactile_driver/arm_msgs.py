"""Conversions between the arm's ROS messages and numpy arrays (used by the commander)."""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseStamped
from nav_msgs.msg import Path
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from tactile_common.finger_axis import axes_from_quaternions
from tactile_common.rotations import matrix_to_quaternion, quaternion_to_matrix, xyzw
from tactile_common.stamps import duration_from_s, stamp_ns  # noqa: F401  (stamp_ns: used by the commander)
from tactile_driver.trajectory import TimedTrajectory


def pose_arrays(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and rotation (3, 3) of a Pose."""
    p = pose.position
    o = pose.orientation
    return np.array([p.x, p.y, p.z], dtype=float), quaternion_to_matrix(xyzw(o))


def pose_stamped(position: np.ndarray, rotation: np.ndarray, frame_id: str, stamp: Time) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in position)
    qx, qy, qz, qw = matrix_to_quaternion(rotation)
    msg.pose.orientation.x, msg.pose.orientation.y = float(qx), float(qy)
    msg.pose.orientation.z, msg.pose.orientation.w = float(qz), float(qw)
    return msg


def path_xyz(msg: Path) -> np.ndarray:
    """(K, 3) positions of a nav_msgs/Path."""
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in msg.poses],
                    dtype=float).reshape(-1, 3)


def path_axes(msg: Path) -> np.ndarray:
    """(K, 3) finger axes of a nav_msgs/Path: each pose's z-axis (tactile_common.finger_axis; an
    all-zero orientation is the vertical finger)."""
    q = np.array([[p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z, p.pose.orientation.w]
                  for p in msg.poses], dtype=float).reshape(-1, 4)
    return axes_from_quaternions(q)


def joint_positions(msg: JointState, names: Sequence[str]) -> Optional[np.ndarray]:
    """Positions of ``names`` (in that order) from a JointState, or None if one is missing/invalid."""
    if len(msg.position) != len(msg.name):
        return None
    index = {n: i for i, n in enumerate(msg.name)}
    try:
        q = np.array([msg.position[index[n]] for n in names], dtype=float)
    except KeyError:
        return None
    return q if np.all(np.isfinite(q)) else None


def joint_velocities(msg: JointState, names: Sequence[str]) -> Optional[np.ndarray]:
    """Velocities of ``names`` (in that order) from a JointState, or None if not sent / invalid."""
    if len(msg.velocity) != len(msg.name) or not len(msg.velocity):
        return None
    index = {n: i for i, n in enumerate(msg.name)}
    try:
        qd = np.array([msg.velocity[index[n]] for n in names], dtype=float)
    except KeyError:
        return None
    return qd if np.all(np.isfinite(qd)) else None


def trajectory_msg(traj: Optional[TimedTrajectory], joint_names: Sequence[str], frame_id: str = "") -> JointTrajectory:
    """A JointTrajectory starting now (stamp 0); ``None`` gives the empty message (stop and hold)."""
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.joint_names = list(joint_names)
    if traj is None:
        return msg
    for t, q, qd in zip(traj.times_s, traj.positions_rad, traj.velocities_rad_s):
        msg.points.append(JointTrajectoryPoint(
            positions=[float(v) for v in q], velocities=[float(v) for v in qd], time_from_start=duration_from_s(float(t))
        ))
    return msg
