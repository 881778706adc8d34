"""Which contacts a graph slide gathered, for the explorer and for ``replay.sh --offline`` (ROS-free).

A slide's report (:class:`tactile_common.cycle.TouchReport`, ``slide_m``
set) names its contact stream: every contact (label 1 on /tactile/contacts)
stamped from ``first_observation_stamp_ns`` (the approach's or the path's
contact, from the driver) to ``observation_stamp_ns`` (the last contact of
the commander's thinned stream), ``contacts`` of them. The explorer's replica
of the estimate and the re-analysis both take exactly those contacts, in
stamp order, so the re-analysed final IoU is the graph run's. The estimator
node takes each contact as it arrives (the same set: stamps in order).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np

from tactile_common.cycle import TouchReport
from tactile_common.slide_goal import decode_path


@dataclass(frozen=True)
class StopReason:
    """Why a slide stopped, as :class:`tactile_driver.slide_servo.SlideStop` shows it (``value``)."""

    value: str


@dataclass(frozen=True)
class GraphSlide:
    """A slide of a graph run: its contacts (CONTACT_DTYPE records, stamp order: the approach's
    contact first), their stamps (ns), the slid length (m) and why it stopped.

    ``points_xyz`` / ``normals_xyz`` / ``n_contacts`` are the slide's own contacts (after the approach's), as
    :class:`tactile_sim.slide.SlideResult` has them offline.
    """

    observations: list
    stamps_ns: list
    slid_m: float
    stop: StopReason

    @property
    def points_xyz(self) -> np.ndarray:
        rows = [[o["x"], o["y"], o["z"]] for o in self.observations[1:]]
        return np.asarray(rows, dtype=float).reshape(-1, 3)

    @property
    def normals_xyz(self) -> np.ndarray:
        rows = [[o["normal_x"], o["normal_y"], o["normal_z"]] for o in self.observations[1:]]
        return np.asarray(rows, dtype=float).reshape(-1, 3)

    @property
    def n_contacts(self) -> int:
        return max(len(self.observations) - 1, 0)


def is_stream(report: TouchReport) -> bool:
    """A slide that touched: its observations are a stream, not one point."""
    return report.is_slide and report.first_observation_stamp_ns is not None \
        and report.observation_stamp_ns is not None


def graph_slide(report: TouchReport, observations: Mapping[int, np.ndarray]) -> Optional[GraphSlide]:
    """The slide's stream from ``observations`` (stamp ns → contact record), or None while it is
    incomplete (the last contact missing, or fewer than ``report.contacts`` in the window)."""
    first, last = int(report.first_observation_stamp_ns), int(report.observation_stamp_ns)
    if last not in observations:
        return None
    stamps = sorted(s for s, o in observations.items() if first <= s <= last and int(o["label"]) == 1)
    if len(stamps) < max(int(report.contacts), 1):
        return None
    return GraphSlide([observations[s] for s in stamps], stamps, float(report.slide_m or 0.0),
                      StopReason(report.slide_stop or "unknown"))


def free_path(path_xyz: Optional[np.ndarray], goal) -> Optional[np.ndarray]:
    """The free-space part of a goal's path (a slide's marker removed; see tactile_common.slide_goal)."""
    if path_xyz is None or goal is None:
        return path_xyz
    p = goal.pose.position
    return decode_path(path_xyz, np.array([p.x, p.y, p.z], dtype=float)).free_path_xyz


def report_of(outcome: str, values: Mapping[str, str]) -> TouchReport:
    """The report of a recorded /arm/touch_done message (its ``message`` and key/values)."""
    return TouchReport.from_values(outcome, values)
