"""The result of one poke, whichever finger made it (world frame, metres).

:class:`tactile_bringup.rig_touch.RigFinger` (the graph's sensing chain) and
:class:`tactile_bringup.sensing.SimulatedFinger` (the motion model) both
return it, so the offline loop has one poke branch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass(frozen=True)
class PokeResult:
    """One poke as the graph senses it (world frame, m).

    ``outcome``: 'contact', 'free_space', 'unreachable' (nothing moved) or 'aborted' (the arm followed
    the path and stopped at its end, ``end_xyz``: the commander refused the approach from there).
    A contact: ``point_xyz``, ``normal_xyz`` (unit outward; NaN when the sensor cannot tell) and
    ``force_n`` of the driver's onset; free space:
    ``point_xyz`` = the probe end (tip centre) and ``sweep_xyz`` = from there back to the approach's
    start. ``end_xyz``: the nominal end (the pre-touch point, or the back-off point after a contact on
    the path; the next touch starts there). ``path_followed_m``: tip path length before a contact on
    the path (None: the path was free). ``approach_m``: approach travel to the contact or full depth.
    ``back_off_m``: tip travel of the back-off after a path contact. A tilted touch
    (tactile_common.finger_axis): ``untilt_m``, ``untilt_s``: tip travel and planned time of the way
    back to the entry point with the finger turned vertical there (0: a vertical finger).
    """

    outcome: str
    point_xyz: np.ndarray
    normal_xyz: np.ndarray
    force_n: float
    sweep_xyz: Optional[np.ndarray]
    end_xyz: np.ndarray
    path_followed_m: Optional[float]
    approach_m: float
    back_off_m: float = 0.0
    reason: str = ""
    untilt_m: float = 0.0
    untilt_s: float = 0.0

    @property
    def contact(self) -> bool:
        return self.outcome == "contact"
