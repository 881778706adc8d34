"""Safety logic of the arm commander (ROS-free): workspace box, stale-state watchdog, e-stop latch.

The box is checked on every tip waypoint before anything is sent: a target
outside is rejected with the offending point, never clamped. A guarded
approach's depth is a bound, not a target: it is shortened to end inside the
box (:meth:`WorkspaceBox.approach_depth_m`), so a plate lying on the table is touched
from above instead of refused because a full-depth approach would end in it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np

from tactile_common.touch_geometry import APPROACH_BOX_INSET_M  # a shortened approach ends this far inside


class OutsideWorkspace(ValueError):
    """A tip point lies outside the safety box.

    Attributes:
        index: index of the first offending point.
        point_xyz: that point (world, m).
        lower_xyz, upper_xyz: the box (the floor included in lower z).
    """

    def __init__(self, index: int, point_xyz: np.ndarray, lower_xyz: np.ndarray, upper_xyz: np.ndarray) -> None:
        self.index = int(index)
        self.point_xyz = np.asarray(point_xyz, dtype=float)
        self.lower_xyz, self.upper_xyz = lower_xyz, upper_xyz
        axes = [
            f"{'xyz'[i]}={self.point_xyz[i]:.6f} not in [{lower_xyz[i]:.6f}, {upper_xyz[i]:.6f}]"
            for i in range(3)
            if not lower_xyz[i] <= self.point_xyz[i] <= upper_xyz[i]
        ] or ["not finite"]
        super().__init__(f"tip point {index} outside the safety box: {', '.join(axes)}")


@dataclass(frozen=True)
class WorkspaceBox:
    """Axis-aligned box for the tip centre (world frame, m), with a floor above the table.

    The effective lower z is max(box z_min, table_z + table_margin + tip_radius).
    """

    lower_xyz: np.ndarray
    upper_xyz: np.ndarray

    @classmethod
    def from_params(cls, x_m: Sequence[float], y_m: Sequence[float], z_m: Sequence[float],
                    table_z_m: float = 0.0, table_margin_m: float = 0.005, tip_radius_m: float = 0.010) -> "WorkspaceBox":
        for name, r in (("x", x_m), ("y", y_m), ("z", z_m)):
            if len(r) != 2 or not r[0] < r[1]:
                raise ValueError(f"safety box {name} range must be [min, max] with min < max, got {list(r)}")
        floor = table_z_m + table_margin_m + tip_radius_m
        lower = np.array([x_m[0], y_m[0], max(z_m[0], floor)], dtype=float)
        upper = np.array([x_m[1], y_m[1], z_m[1]], dtype=float)
        if lower[2] >= upper[2]:
            raise ValueError(f"safety box floor {lower[2]:.3f} m is not below its top {upper[2]:.3f} m")
        return cls(lower, upper)

    @classmethod
    def of_commander(cls, config: Any) -> "WorkspaceBox":
        """The arm commander's box: from a configuration with its ``box_x_m``, ``box_y_m``, ``box_z_m``,
        ``table_z_m``, ``table_margin_m`` and ``tip_radius_m`` (a ``CommanderConfig``)."""
        c = config
        return cls.from_params(c.box_x_m, c.box_y_m, c.box_z_m, c.table_z_m, c.table_margin_m, c.tip_radius_m)

    def inside(self, points_xyz: np.ndarray, slack_m: float = 0.0) -> np.ndarray:
        """(N,) bool: point inside the box grown by ``slack_m`` on every face (NaN is outside)."""
        p = np.atleast_2d(np.asarray(points_xyz, dtype=float))
        return np.all((p >= self.lower_xyz - slack_m) & (p <= self.upper_xyz + slack_m), axis=1)

    def reach_m(self, start_xyz: np.ndarray, direction_xyz: np.ndarray) -> float:
        """How far the tip can go from ``start_xyz`` (inside the box) along ``direction_xyz`` and stay
        inside: min over axes of the distance to the face it heads for (inf along no axis; 0 outside)."""
        p, d = np.asarray(start_xyz, dtype=float), np.asarray(direction_xyz, dtype=float)
        d = d / np.linalg.norm(d)
        if not self.inside(p)[0]:
            return 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            to_face = np.where(d > 0, (self.upper_xyz - p) / d, np.where(d < 0, (self.lower_xyz - p) / d, np.inf))
        return float(np.min(to_face))

    def approach_depth_m(self, start_xyz: np.ndarray, direction_xyz: np.ndarray, depth_m: float) -> float:
        """``depth_m``, or less so that an approach from ``start_xyz`` (inside) along ``direction_xyz`` ends
        ``APPROACH_BOX_INSET_M`` inside the box (negative when it cannot)."""
        return min(float(depth_m), self.reach_m(start_xyz, direction_xyz) - APPROACH_BOX_INSET_M)

    def check(self, points_xyz: np.ndarray, first: int = 0, slack_m: float = 0.0) -> None:
        """Raise :class:`OutsideWorkspace` for the first point (from index ``first`` on) outside the box
        grown by ``slack_m`` (the IK's accuracy, for waypoints it computed towards targets inside)."""
        p = np.atleast_2d(np.asarray(points_xyz, dtype=float))
        ok = self.inside(p, slack_m)
        ok[:first] = True
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            raise OutsideWorkspace(i, p[i], self.lower_xyz, self.upper_xyz)


class Watchdog:
    """Stale-input detector: stale when nothing was fed for longer than ``timeout_s``.

    Before the first ``feed`` it is stale (no state = no motion).
    """

    def __init__(self, timeout_s: float) -> None:
        if timeout_s <= 0:
            raise ValueError("watchdog timeout must be positive")
        self.timeout_s = float(timeout_s)
        self._last_s: Optional[float] = None

    def feed(self, now_s: float) -> None:
        self._last_s = float(now_s)

    def age_s(self, now_s: float) -> float:
        return np.inf if self._last_s is None else float(now_s) - self._last_s

    def is_stale(self, now_s: float) -> bool:
        return self.age_s(now_s) > self.timeout_s


class EStopLatch:
    """E-stop state: engaged by ``True``; only an explicit ``False`` releases it."""

    def __init__(self) -> None:
        self.engaged = False
        self.count = 0  # times it was engaged

    def set(self, value: bool) -> bool:
        """Apply a message; returns True when this engages a released latch."""
        rising = bool(value) and not self.engaged
        self.engaged = bool(value)
        self.count += int(rising)
        return rising
