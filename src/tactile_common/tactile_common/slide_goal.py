"""How a slide goal travels from the planner to the arm commander (ROS-free).

World frame, metres. A poke goal is unchanged: ``/planner/goal`` (PoseStamped)
is the pre-touch point with orientation x = the approach direction (−n), and
``/planner/path`` (nav_msgs/Path, same stamp) is the free-space path, ending
at the pre-touch point.

A slide goal (planner parameter ``touch: slide``) adds, to the same pair:

- orientation: x = the approach direction (−n), **y = the slide direction**
  d (the unit start tangent, made orthogonal to x), z = x × y
  (:func:`slide_rotation`), so a viewer shows which way the finger will slide;
- **the slide vector as the path's last segment**: after the pre-touch point
  the path has one more pose, the *slide marker*, at pre-touch + L·d, where
  L (m) is the planned slide length (:func:`encode_path`). The commander
  splits it off (:func:`decode_path`): a path whose second-to-last pose is the
  goal's position and whose last pose is elsewhere is a slide; the last
  segment gives d (its direction) and L (its length); the poses before it are
  the free-space path. A poke's path ends at the goal position, so it never
  decodes as a slide.

The marker is not a place the finger goes: the slide itself follows the
surface from the approach's contact (tactile_driver.slide_servo).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

#: Positions closer than this are the same point (m).
SAME_POINT_M = 1e-6


@dataclass(frozen=True)
class DecodedPath:
    """A goal path split into the free-space path (K, 3) and the slide (None: a poke)."""

    free_path_xyz: np.ndarray
    slide_direction_xyz: Optional[np.ndarray] = None  # unit, world
    slide_length_m: float = float("nan")

    @property
    def is_slide(self) -> bool:
        return self.slide_direction_xyz is not None


def slide_rotation(approach_xyz: np.ndarray, direction_xyz: np.ndarray) -> np.ndarray:
    """Rotation (columns = goal x, y, z in world): x = approach, y = direction ⟂ x, z = x × y.

    Raises:
        ValueError: a zero or non-finite vector, or a direction along the approach.
    """
    x = np.asarray(approach_xyz, dtype=float).reshape(3)
    d = np.asarray(direction_xyz, dtype=float).reshape(3)
    nx = float(np.linalg.norm(x))
    if not (np.isfinite(nx) and nx > 1e-9):
        raise ValueError(f"slide goal: approach {x.tolist()} must be a finite non-zero vector")
    x = x / nx
    y = d - float(d @ x) * x
    ny = float(np.linalg.norm(y))
    if not (np.isfinite(ny) and ny > 1e-6):
        raise ValueError(f"slide goal: direction {d.tolist()} must be finite and not along the approach")
    y = y / ny
    return np.stack([x, y, np.cross(x, y)], axis=1)


def encode_path(path_xyz: np.ndarray, goal_xyz: np.ndarray, direction_xyz: np.ndarray,
                length_m: float) -> np.ndarray:
    """The goal path of a slide: the free-space path (ending at ``goal_xyz``), then the marker.

    Raises:
        ValueError: a length that is not finite and > 0, a zero direction, or a path that does
            not end at the goal position.
    """
    P = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
    g = np.asarray(goal_xyz, dtype=float).reshape(3)
    d = np.asarray(direction_xyz, dtype=float).reshape(3)
    nd = float(np.linalg.norm(d))
    if not (np.isfinite(length_m) and length_m > SAME_POINT_M):
        raise ValueError(f"slide goal: length {length_m} must be a finite number > {SAME_POINT_M} m")
    if not (np.isfinite(nd) and nd > 1e-9):
        raise ValueError(f"slide goal: direction {d.tolist()} must be a finite non-zero vector")
    if len(P) == 0 or float(np.linalg.norm(P[-1] - g)) > SAME_POINT_M:
        P = np.vstack([P, g[None]])  # the path ends at the pre-touch point
    return np.vstack([P, (g + float(length_m) * d / nd)[None]])


def decode_path(path_xyz: np.ndarray, goal_xyz: np.ndarray) -> DecodedPath:
    """Split a goal path (module docstring); a path without a marker is a poke's, returned whole."""
    P = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
    g = np.asarray(goal_xyz, dtype=float).reshape(3)
    if len(P) >= 2 and float(np.linalg.norm(P[-2] - g)) <= SAME_POINT_M:
        seg = P[-1] - g
        length = float(np.linalg.norm(seg))
        if np.isfinite(length) and length > SAME_POINT_M:
            return DecodedPath(P[:-1].copy(), seg / length, length)
    return DecodedPath(P.copy())
