"""The arm's links behind the flange as cylinders about the finger axis (shared by the planner, the
arm commander and the evaluator; the planner's estimate checks are in :mod:`tactile_planner.wrist`).

World frame, metres. The finger axis a is the unit vector from the tip centre towards the flange; the
flange is at x + L·a (L: the rod, the commander's ``tip_offset_m``). A band (t0, t1, ρ) is the cylinder
of radius ρ about the axis from x + (L + t0)·a to x + (L + t1)·a (t: metres behind the flange).

On the Panda, joint 7 turns about the finger's own axis, so link 7 and link 6 lie inside fixed
cylinders about it whatever the IK picks: link 7 reaches 9.1 cm from the axis up to 5 cm behind the
flange, link 6 13.9 cm from 5 to 15 cm and 10.4 cm on to 19 cm (example-robot-data's collision meshes;
the radii below add 2 mm; tests/planner/test_wrist.py places the meshes by forward kinematics at random
joints and checks they stay inside). Link 5 and below move with joint 6: not modelled.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

#: (t0, t1, radius) in metres behind the flange: the Panda's link 7 and link 6 (module docstring).
PANDA_WRIST_BANDS_M = ((0.0, 0.05, 0.093), (0.05, 0.15, 0.141), (0.15, 0.19, 0.106))
#: The same, flat [t0, t1, radius, ...]: the ROS parameters' form.
PANDA_WRIST_BANDS_FLAT_M = tuple(v for band in PANDA_WRIST_BANDS_M for v in band)


def bands_from_flat(values: Sequence[float], name: str = "wrist bands") -> tuple:
    """((t0, t1, radius), ...) from the flat list [t0, t1, radius, ...] of parameter ``name``.

    Raises:
        ValueError: not whole triples, or a band with t0 < 0, t1 ≤ t0 or a negative radius.
    """
    v = [float(x) for x in values]
    if len(v) % 3 or not v:
        raise ValueError(f"{name} must be triples [t0, t1, radius, ...] (m), got {len(v)} values")
    bands = tuple(tuple(v[i:i + 3]) for i in range(0, len(v), 3))
    for t0, t1, r in bands:
        if not (np.isfinite([t0, t1, r]).all() and 0.0 <= t0 < t1 and r >= 0.0):
            raise ValueError(f"{name}: band ({t0}, {t1}, {r}) needs 0 ≤ t0 < t1 and radius ≥ 0")
    return bands


def wrist_lowest_z_m(tip_xyz: np.ndarray, axis_xyz: np.ndarray, bands_m: tuple, rod_length_m: float) -> np.ndarray:
    """(N,) the lowest point of the bands' cylinders for (N, 3) tip centres and (3,) or (N, 3) unit axes:
    min over bands and t ∈ {t0, t1} of z + (L + t)·a_z − ρ·√(1 − a_z²) (exact: a cylinder's lowest point
    lies on the rim of one of its end discs)."""
    x = np.asarray(tip_xyz, float).reshape(-1, 3)
    a = np.broadcast_to(np.asarray(axis_xyz, float).reshape(-1, 3), x.shape)
    side = np.sqrt(np.clip(1.0 - a[:, 2] ** 2, 0.0, 1.0))
    low = np.full(len(x), np.inf)
    for t0, t1, rho in bands_m:
        ends = np.minimum(x[:, 2] + (rod_length_m + t0) * a[:, 2], x[:, 2] + (rod_length_m + t1) * a[:, 2])
        low = np.minimum(low, ends - rho * side)
    return low
