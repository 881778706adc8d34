"""From raw taxel counts to a contact on the fingertip (ROS-free).

Per frame (all taxel quantities vectorised over the N taxels):

1. Calibration: the first ``calibration_frames`` frames (no contact) give each
   taxel's baseline b_i (mean) and noise s_i (std, floored at
   ``min_noise_counts``).
2. Signal d_i = v_i - b_i. Taxel i is *active* if d_i > k s_i
   (``noise_gate_sigma`` = k), it is not ignored, and at least one
   neighbouring taxel is active too (a lone spike is not a touch).
   Ignored: *dead* taxels (saturated 0 or 65535 or zero noise during
   calibration) and *stuck* ones (value unchanged for ``stuck_frames`` frames;
   a live taxel always shows noise).
3. Force F = sum_active d_i / ``counts_per_newton`` (N).
4. Hysteresis: contact turns on when F >= ``on_threshold_n`` with at least
   ``min_active_taxels`` active, off when F < ``off_threshold_n``. Only the
   rising edge (onset) yields a :class:`ContactEstimate`.
5. Location: c = sum_i d_i p_i / sum_i d_i over the active taxels (the
   pressure-weighted mean of taxel positions, inside the finger), projected
   back to the finger surface along the direction from the finger axis
   (:meth:`TaxelLayout.project_to_surface`); the finger normal there is the
   geometric one. With a ring layout (2D rig, no cap) the height is the
   band's mid height (z = 0 for the default rings: the tip centre), so 2D
   contacts carry exactly the tip's z.
6. Rim (hemisphere layouts): a centre within ``rim_margin_m`` of the top of
   the sensorised band means the object presses on the band's upper rim (an
   object surface facing down, met by the side of the finger): the point is
   good to ~1 mm but the geometric normal there is horizontal whatever the
   surface's slope (up to 35° off in simulation), so the normal is reported
   unknown (NaN) and the estimator uses the point alone.
7. Indentation (``skin_stiffness_pa_per_m`` > 0): the skin is pressed in by δ
   under the force F, so the surface point lies δ inside the object; it is
   moved δ in along the finger normal (:mod:`tactile_driver.skin`; not at the
   rim, whose normal is not known).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from tactile_common.touch_geometry import back_off_target  # noqa: F401  (re-exported)

from tactile_driver.skin import SkinIndentation
from tactile_driver.taxels import TaxelLayout

_SATURATED = 0xFFFF


@dataclass(frozen=True)
class ContactConfig:
    """Detector parameters (the driver's ``tactile_sensor.yaml`` holds the defaults)."""

    counts_per_newton: float = 10000.0
    on_threshold_n: float = 0.05
    off_threshold_n: float = 0.025
    noise_gate_sigma: float = 4.0
    min_noise_counts: float = 1.0
    min_active_taxels: int = 2
    calibration_frames: int = 40
    stuck_frames: int = 40
    neighbour_factor: float = 1.8  # neighbours: closer than factor x nearest-taxel distance
    rim_margin_m: float = 0.001  # hemisphere: centre this close to the band top = rim contact, normal unknown
    skin_stiffness_pa_per_m: float = 0.0  # > 0: the contact moved in by the skin's indentation (0 = not)
    skin_margin_m: float = 0.00625  # how far the compliant skin reaches beyond the sensorised band

    def validate(self) -> "ContactConfig":
        if self.counts_per_newton <= 0:
            raise ValueError("counts_per_newton must be > 0")
        if not self.rim_margin_m >= 0:
            raise ValueError("rim_margin_m must be >= 0")
        if not (self.skin_stiffness_pa_per_m >= 0 and self.skin_margin_m >= 0):
            raise ValueError("skin_stiffness_pa_per_m and skin_margin_m must be >= 0")
        if not 0 < self.off_threshold_n <= self.on_threshold_n:
            raise ValueError("need 0 < off_threshold_n <= on_threshold_n (hysteresis)")
        if self.calibration_frames < 2 or self.stuck_frames < 2:
            raise ValueError("calibration_frames and stuck_frames must be >= 2")
        return self


@dataclass(frozen=True)
class ContactEstimate:
    """A contact in the fingertip frame.

    ``point_m``: contact location on the finger surface, moved in by
    ``indentation_m`` (the skin's compression under the force, 0 unless
    ``skin_stiffness_pa_per_m`` > 0: then it is on the object's surface);
    ``finger_normal``: outward unit normal of the finger there (the object's
    outward normal is its negative); ``force_n``: estimated normal force.
    """

    point_m: np.ndarray
    finger_normal: np.ndarray
    force_n: float
    n_active: int
    indentation_m: float = 0.0

    def to_world(self, position_m: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World contact point and the object's outward unit normal there.

        With the fingertip pose (p, R) (fingertip -> world):
        x_w = p + R x_tip, n_object = -R n_finger.
        """
        R = np.asarray(rotation, dtype=float)
        point = np.asarray(position_m, dtype=float) + R @ self.point_m
        return point, -(R @ self.finger_normal)


class ContactDetector:
    """Baseline calibration, stuck/dead taxels, hysteresis and contact location."""

    def __init__(self, layout: TaxelLayout, config: ContactConfig = ContactConfig()) -> None:
        self.layout = layout
        self.config = config.validate()
        n = layout.n_taxels
        d = np.linalg.norm(layout.positions_m[:, None, :] - layout.positions_m[None, :, :], axis=2)
        np.fill_diagonal(d, np.inf)
        radius = config.neighbour_factor * float(np.min(d, axis=1).max())
        self._neighbours = (d < radius).astype(np.float64)  # (N, N), zero diagonal
        self._skin = (SkinIndentation(layout, config.skin_stiffness_pa_per_m, config.skin_margin_m)
                      if config.skin_stiffness_pa_per_m > 0 else None)
        self._calib: list[np.ndarray] = []
        self.baseline = np.zeros(n)
        self.noise = np.ones(n)
        self.dead = np.zeros(n, dtype=bool)
        self._last = np.full(n, -1, dtype=np.int64)
        self._same_run = np.zeros(n, dtype=np.int64)
        self.in_contact = False
        self.force_n = 0.0
        self.n_active = 0
        #: The latest estimate while in contact (every frame, not only the onset; None out of
        #: contact): what a slide's tactile servo reads each control tick.
        self.current: Optional[ContactEstimate] = None

    @property
    def calibrated(self) -> bool:
        return len(self._calib) >= self.config.calibration_frames

    @property
    def stuck(self) -> np.ndarray:
        """(N,) bool: taxels whose value has not changed for ``stuck_frames`` frames."""
        return self._same_run >= self.config.stuck_frames

    @property
    def ignored(self) -> np.ndarray:
        return self.dead | self.stuck

    def recalibrate(self) -> None:
        """Collect a new baseline from the next frames (the finger must be free)."""
        self._calib = []
        self.in_contact = False
        self.current = None

    def update(self, values: np.ndarray) -> Optional[ContactEstimate]:
        """Process one frame of raw counts; the estimate at a contact onset, else None.

        Raises:
            ValueError: the frame has the wrong number of taxels.
        """
        v = np.asarray(values)
        if v.shape != (self.layout.n_taxels,):
            raise ValueError(f"frame has {v.size} taxels, the layout has {self.layout.n_taxels}")
        v = v.astype(np.int64)
        same = v == self._last
        self._same_run = np.where(same & (v != _SATURATED), self._same_run + 1, 0)
        self._last = v
        if not self.calibrated:
            self._calib.append(v.astype(np.float64))
            if self.calibrated:
                self._finish_calibration()
            return None
        signal = v - self.baseline
        active = (signal > self.config.noise_gate_sigma * self.noise) & ~self.ignored
        active &= (self._neighbours @ active) > 0
        self.n_active = int(active.sum())
        self.force_n = float(signal[active].sum() / self.config.counts_per_newton)
        if self.in_contact:
            if self.force_n < self.config.off_threshold_n:
                self.in_contact = False
                self.current = None
            else:
                self.current = self._locate(signal, active) or self.current
            return None
        if self.force_n < self.config.on_threshold_n or self.n_active < self.config.min_active_taxels:
            return None
        est = self._locate(signal, active)
        if est is None:
            return None
        self.in_contact = True
        self.current = est
        return est

    def _locate(self, signal: np.ndarray, active: np.ndarray) -> Optional[ContactEstimate]:
        """Steps 5-6 of the module docstring on one frame's signal (None: no direction)."""
        if not active.any():
            return None
        w = signal[active]
        centre = (w @ self.layout.positions_m[active]) / w.sum()
        if not self.layout.hemisphere:  # 2D rig: the contour is sensed at the band's mid height
            centre[2] = 0.5 * sum(self.layout.axis_z_range_m)
        point, normal = self.layout.project_to_surface(centre[None, :])
        if not np.all(np.isfinite(point)):
            return None  # a pressure centroid on the axis has no direction
        depth = 0.0
        if self.layout.hemisphere and centre[2] >= self.layout.axis_z_range_m[1] - self.config.rim_margin_m:
            normal = np.full_like(normal, np.nan)  # on the rim: the surface's slope is not sensed
        elif self._skin is not None:
            depth = self._skin.depth_m(self.force_n, normal[0])
            point = point - depth * normal
        return ContactEstimate(point_m=point[0], finger_normal=normal[0], force_n=self.force_n,
                               n_active=self.n_active, indentation_m=depth)

    def _finish_calibration(self) -> None:
        c = np.asarray(self._calib)
        self.baseline = c.mean(axis=0)
        std = c.std(axis=0)
        self.dead = (std == 0) | np.any(c >= _SATURATED, axis=0) | np.any(c <= 0, axis=0)
        self.noise = np.maximum(std, self.config.min_noise_counts)
