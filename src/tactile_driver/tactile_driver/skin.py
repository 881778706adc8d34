"""How far the fingertip's skin is pressed in under a force (ROS-free).

A contact is located on the *undeformed* finger surface (``contact.py``), but
the skin is compliant: to push with force F the finger has moved a depth δ
into the object, so that point lies δ inside the object's surface (in
simulation 0.1–0.4 mm at the 0.05 N onset, ~0.5 mm at a slide's 0.15 N: every
contact sits that far inside the true surface unless the driver reads δ off).

Spring skin of stiffness k (pressure per metre of compression, Pa/m) against a
plane with outward normal −n (n: the finger's outward normal at the contact):
with the finger surface sampled as points s with areas A (the sensorised band
extended by the skin's margin, and the cap), the plane at height L = h_max − δ
along n (h = s·n) compresses each sample by max(0, h − L), so

    F(δ) = k Σ_s A_s max(0, h_s − (h_max − δ)),

continuous, piecewise linear in L between the sorted h and increasing in δ; δ
is read off exactly by inverting it. For a sphere of radius r this is the
cap's F = π k r δ², for the side band the cylinder's (4/3) k H √(2r) δ^{3/2}.
The contact on the object is then the surface point moved δ in along n.
"""

from __future__ import annotations

import numpy as np

from tactile_driver.taxels import TaxelLayout


class SkinIndentation:
    """The skin's compression δ (m) under a normal force against a plane, for one finger."""

    def __init__(self, layout: TaxelLayout, stiffness_pa_per_m: float, margin_m: float,
                 spacing_m: float = 0.0005) -> None:
        if not (np.isfinite(stiffness_pa_per_m) and stiffness_pa_per_m > 0):
            raise ValueError(f"skin stiffness must be > 0 Pa/m, got {stiffness_pa_per_m}")
        if not margin_m >= 0:
            raise ValueError(f"skin margin must be >= 0 m, got {margin_m}")
        self.stiffness_pa_per_m = float(stiffness_pa_per_m)
        self._points_m, _, self._area_m2 = layout.surface_samples(spacing_m, margin_m)

    def depth_m(self, force_n: float, finger_normal: np.ndarray) -> float:
        """δ with F(δ) = ``force_n`` for the plane facing the unit ``finger_normal`` (fingertip frame)."""
        if not force_n > 0:
            return 0.0
        h = self._points_m @ np.asarray(finger_normal, dtype=float)
        order = np.argsort(-h)
        h, a = h[order], self._area_m2[order]
        cum_a, cum_ah = np.cumsum(a), np.cumsum(a * h)
        # F at the breakpoints L = h_j: the samples above h_j (the first j + 1) compressed by h − h_j
        f_break = self.stiffness_pa_per_m * (cum_ah - h * cum_a)
        j = int(np.searchsorted(f_break, force_n, side="right")) - 1  # ≥ 0: f_break[0] = 0 < force_n
        # between h_{j+1} and h_j the set above L is fixed: F = k (Σ A h − L Σ A), linear in L
        level = (cum_ah[j] - force_n / self.stiffness_pa_per_m) / cum_a[j]
        return float(h[0] - level)
