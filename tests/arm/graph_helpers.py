"""Helpers for the arm graph tests: goal + path messages, touch_done parsing."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path

from tactile_common.stamps import time_from_ns
from tactile_driver.arm_msgs import pose_stamped


def goal_and_path(pre_touch_xyz, approach_dir, path_xyz, stamp_ns: int):
    """PoseStamped whose x-axis is ``approach_dir`` (z kept near world +z) and its Path, same stamp."""
    x = np.asarray(approach_dir, float) / np.linalg.norm(approach_dir)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    R = np.column_stack([x, y, np.cross(x, y)])
    stamp = time_from_ns(stamp_ns)
    goal = pose_stamped(np.asarray(pre_touch_xyz, float), R, "world", stamp)
    path = Path()
    path.header = goal.header
    for p in np.asarray(path_xyz, float):
        path.poses.append(pose_stamped(p, np.eye(3), "world", stamp))
    return goal, path


def done_values(msg) -> dict:
    return {kv.key: kv.value for kv in msg.values}
