"""The motion model shared by the offline loop and the arm commander's accounting.

Travel is the fingertip path length in metres: the free-space path, then the
guarded approach and the retract along the same line. Time in seconds: the
path at ``tip_speed_mps``, approach + retract at ``approach_speed_mps``, plus
``dwell_s`` per touch (docs/architecture.md, "Motion model").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np


@dataclass(frozen=True)
class MotionModel:
    tip_speed_mps: float = 0.10
    approach_speed_mps: float = 0.02
    dwell_s: float = 0.5

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> "MotionModel":
        """From the arm commander's parameters (same names)."""
        fields = cls.__dataclass_fields__
        return cls(**{k: float(params[k]) for k in fields if k in params})

    def touch_time_s(self, path_m: float, approach_m: float) -> float:
        """Time of one touch: path, approach and retract (approach_m each way), dwell."""
        return path_m / self.tip_speed_mps + 2.0 * approach_m / self.approach_speed_mps + self.dwell_s

    def path_contact_time_s(self, path_m: float, back_off_m: float) -> float:
        """Time of a touch whose path met the object: path to the contact, back-off at approach speed."""
        return path_m / self.tip_speed_mps + back_off_m / self.approach_speed_mps


def polyline_length_m(points_xyz: np.ndarray) -> float:
    """Length of a polyline given as (K, 3) points (0 for fewer than two)."""
    points_xyz = np.asarray(points_xyz, dtype=float)
    if len(points_xyz) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(points_xyz, axis=0), axis=1).sum())
