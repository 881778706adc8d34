"""The geometry and the time of a touch, in one place for the planner, the commander, the offline loop and the report.

World frame, metres, seconds. A touch aims at a candidate point ``c`` on the
estimated surface with outward unit normal ``n``:

- **pre-touch point** (tip centre): ``p = c + (standoff_m + tip_radius_m)·n``:
  the finger's skin is ``standoff_m`` off the estimated surface;
- **approach**: from ``p`` along ``−n`` for ``approach_length_m =
  standoff_m + max_depth_m``, i.e. **``max_depth_m`` is how far the finger's
  skin may go beyond the estimated surface point** (the tip centre ends at
  ``c − (max_depth_m − tip_radius_m)·n``); it stops earlier on contact; no
  contact by then is a free-space observation (the tip centre at the end).
  The arm's safety box may shorten it (the depth is a bound, not a target),
  down to ``min_approach_m = standoff_m + max_depth_m / 2``: an approach that
  cannot take the skin at least half the depth beyond the estimated surface
  cannot test it, and the touch is unreachable;
- **retract**: back to ``p`` along the same line;
- **back-off** after a contact met on a free-space path: the tip centre moves
  to ``c' + (tip_radius_m + standoff_m)·(t − c')/|t − c'|`` for the contact
  ``c'`` and the tip centre ``t`` where the motion stopped (for a round tip
  ``t − c'`` is the surface normal, whatever normal the sensor reported).

Time (:class:`MotionModel`): the free-space path at ``tip_speed_mps``, the
approach and retract (or back-off) at ``approach_speed_mps``, plus
``dwell_s`` at the end of an approach; a **slide** after the approach's
contact adds its slid length at ``slide_speed_mps`` and ends with a back-off
(``slide_time_s``).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Mapping, Optional

import numpy as np


#: A guarded approach that the safety box shortens ends this far inside the box (m): IK waypoints deviate
#: from the line by up to the IK's tolerance (the commander, ``ArmMotions.approach_depth_m``). The planner
#: keeps its targets' shortest approaches inside by the same amount, or the commander refuses them.
APPROACH_BOX_INSET_M = 5e-4


def _from(cls, params: Mapping[str, Any]):
    return cls(**{f.name: float(params[f.name]) for f in fields(cls) if f.name in params})


@dataclass(frozen=True)
class TouchGeometry:
    tip_radius_m: float = 0.010
    standoff_m: float = 0.010
    max_depth_m: float = 0.030

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> "TouchGeometry":
        """From the nodes' shared parameters (same names, under ``/**`` in the mode's YAML)."""
        return _from(cls, params)

    @property
    def approach_length_m(self) -> float:
        """Tip-centre travel of a full-depth approach: ``standoff_m + max_depth_m``."""
        return self.standoff_m + self.max_depth_m

    @property
    def min_approach_m(self) -> float:
        """The shortest approach worth making when the safety box shortens one: ``standoff_m + max_depth_m / 2``."""
        return self.standoff_m + 0.5 * self.max_depth_m

    @property
    def pretouch_offset_m(self) -> float:
        """Tip centre to the candidate at the pre-touch point: ``standoff_m + tip_radius_m``."""
        return self.standoff_m + self.tip_radius_m

    def pretouch_xyz(self, candidate_xyz: np.ndarray, normal_xyz: np.ndarray) -> np.ndarray:
        """Pre-touch tip centre(s) ``c + (standoff + r)·n`` for (…, 3) candidates and unit normals."""
        return np.asarray(candidate_xyz, dtype=float) + self.pretouch_offset_m * np.asarray(normal_xyz, dtype=float)

    def back_off_xyz(self, contact_xyz: np.ndarray, tip_xyz: np.ndarray) -> Optional[np.ndarray]:
        """Where the tip centre goes to leave a contact met on a path (None: no direction)."""
        return back_off_target(contact_xyz, tip_xyz, self.pretouch_offset_m)


def back_off_target(contact_xyz: np.ndarray, tip_xyz: np.ndarray, distance_m: float) -> Optional[np.ndarray]:
    """Where the tip centre goes to leave a contact: c + distance_m·(tip − c)/|tip − c| (world frame).

    For a round fingertip, tip − c is the object's outward normal at the
    contact whatever normal the detector reported, so with distance_m = tip
    radius + clearance the skin ends ``clearance`` off the surface. None when
    the contact is not finite or sits at the tip centre (no direction).
    """
    c = np.asarray(contact_xyz, dtype=float).reshape(3)
    away = np.asarray(tip_xyz, dtype=float).reshape(3) - c
    n = float(np.linalg.norm(away))
    if not (np.all(np.isfinite(c)) and np.isfinite(n) and n > 1e-6):
        return None
    return c + distance_m * away / n


@dataclass(frozen=True)
class MotionModel:
    """Robot time of the motions of a touch (see the module docstring)."""

    tip_speed_mps: float = 0.10
    approach_speed_mps: float = 0.02
    dwell_s: float = 0.5
    slide_speed_mps: float = 0.05

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> "MotionModel":
        """From the arm commander's parameters (same names)."""
        return _from(cls, params)

    def touch_time_s(self, path_m: float, approach_m: float) -> float:
        """Time of one touch: path, approach and retract (approach_m each way), dwell."""
        return path_m / self.tip_speed_mps + 2.0 * approach_m / self.approach_speed_mps + self.dwell_s

    def slide_time_s(self, path_m, approach_m, slide_m, retract_m):
        """Time of a slide touch: path, approach, dwell at contact, slide at ``slide_speed_mps``,
        retract (back-off) at approach speed. Arrays broadcast (the planner's candidates)."""
        return (np.asarray(path_m) / self.tip_speed_mps + (np.asarray(approach_m) + np.asarray(retract_m))
                / self.approach_speed_mps + np.asarray(slide_m) / self.slide_speed_mps + self.dwell_s)

    def path_contact_time_s(self, path_m: float, back_off_m: float) -> float:
        """Time of a touch whose path met the object: path to the contact, back-off at approach speed."""
        return path_m / self.tip_speed_mps + back_off_m / self.approach_speed_mps


def polyline_length_m(points_xyz: np.ndarray) -> float:
    """Length of a polyline given as (K, 3) points (0 for fewer than two)."""
    points_xyz = np.asarray(points_xyz, dtype=float)
    if len(points_xyz) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(points_xyz, axis=0), axis=1).sum())


def rod_points(tip_xyz: np.ndarray, start_m: float, length_m: float, step_m: float,
               axis_xyz: Optional[np.ndarray] = None) -> np.ndarray:
    """(M, K, 3) points on the finger's rod above (M, 3) tip centres, world frame: along the finger axis
    (unit, from the tip towards the flange; ``axis_xyz`` (3,) or one per tip (M, 3); None = vertical, +z)
    from ``start_m`` past the centre (the tip's top: its radius) up to ``length_m`` (the flange), every
    ``step_m``."""
    up = start_m + np.arange(0.0, max(length_m - start_m, 0.0) + 1e-12, step_m)
    tips = np.asarray(tip_xyz, dtype=float).reshape(-1, 3)
    if axis_xyz is None:
        return tips[:, None, :] + up[None, :, None] * np.array([0.0, 0.0, 1.0])
    axis = np.broadcast_to(np.asarray(axis_xyz, dtype=float).reshape(-1, 3), tips.shape)
    return tips[:, None, :] + up[None, :, None] * axis[:, None, :]

