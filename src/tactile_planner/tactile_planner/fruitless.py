"""Touches that taught the estimate nothing at their target, and the candidates near them (ROS-free).

A touch aims at a target c of the estimated surface. If the next map's
variance of f at c is still at least ``var_ratio`` times what it was when c
was chosen, the finger did not sense c: its path met the object elsewhere
and the slide from there circled a hole it had circled before, or the
contact was lost at once on a rim, its one contact a duplicate. The map is
then (nearly) the same, so the same choice, or one a few millimetres away,
would follow again and again: a stall. Candidates within ``radius_m`` of
such a target are set aside (the planner revisits them only when nothing
else is left, like the targets chosen before).

Each decision k compares the map against decision k − 1's aim, and only when
the history it is handed (the visited targets, :class:`TouchPlanner`) ends
with that aim: a request planned again after a planner restart (the same
history) marks nothing. The judgments so far and the last aim's variance go
out with each answer and come back with the next request (:meth:`restore`),
so a restarted planner judges as the one that lived through the run.
Lattice variance, linear interpolation (bilinear 2D, trilinear 3D), world
frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from .maps import MapLattice


def variance_at(lattice: MapLattice, xyz: np.ndarray) -> float:
    """Variance of f (m²) at one world point, interpolated on the lattice (nan outside it)."""
    f = RegularGridInterpolator(lattice.axes, lattice.variance_m2, bounds_error=False, fill_value=np.nan)
    return float(f(np.asarray(xyz, dtype=float)[None, : lattice.dim])[0])


@dataclass
class _Aim:
    decision: int  # the decision that chose it (0-based)
    target_xyz: np.ndarray
    variance_m2: float  # on that decision's map


@dataclass
class FruitlessTouches:
    """The targets of touches after which the variance at the target did not drop (module docstring)."""

    var_ratio: float = 0.9
    radius_m: float = 0.02
    targets: list = field(default_factory=list)  # (decision, target xyz)
    _aim: Optional[_Aim] = None

    def reset(self) -> None:
        self.targets, self._aim = [], None

    def restore(self, targets_xyz: Optional[np.ndarray], last_aim_var_m2: Optional[float],
                visited: Sequence[np.ndarray]) -> None:
        """Take the judgments and the last aim's variance from a request (the planner's last answer):
        the aim is the last visited target."""
        if targets_xyz is not None:
            self.targets = [(-1, np.asarray(t, dtype=float).copy())
                            for t in np.asarray(targets_xyz, dtype=float).reshape(-1, 3)]
        self._aim = None
        if last_aim_var_m2 is not None and len(visited):
            self._aim = _Aim(len(visited) - 1, np.asarray(visited[-1], dtype=float).copy(), float(last_aim_var_m2))

    def targets_xyz(self) -> np.ndarray:
        """(F, 3) the targets judged fruitless, in the order judged."""
        return np.array([t for _, t in self.targets], dtype=float).reshape(-1, 3)

    def note_map(self, lattice: MapLattice, visited: Sequence[np.ndarray]) -> None:
        """Before decision ``len(visited)``: judge the previous aim on this map; forget what lies beyond
        the history (a planner handed an earlier one)."""
        k = len(visited)
        self.targets = [(d, t) for d, t in self.targets if d < k]  # touches the history holds
        aim, self._aim = self._aim, None
        if (self.radius_m <= 0 or aim is None or aim.decision != k - 1
                or not np.allclose(visited[-1], aim.target_xyz)):
            return
        now = variance_at(lattice, aim.target_xyz)
        if np.isfinite(now) and np.isfinite(aim.variance_m2) and now >= self.var_ratio * aim.variance_m2:
            self.targets.append((aim.decision, aim.target_xyz.copy()))

    def aimed(self, decision: int, target_xyz: np.ndarray, lattice: MapLattice) -> float:
        """Decision ``decision`` chose ``target_xyz`` on ``lattice``; returns the variance there (m²)."""
        target = np.asarray(target_xyz, dtype=float).copy()
        self._aim = _Aim(int(decision), target, variance_at(lattice, target))
        return self._aim.variance_m2

    def near(self, target_xyz: np.ndarray, dim: int) -> np.ndarray:
        """(M,) bool: candidates within ``radius_m`` of a fruitless touch's target (2D: in the plane)."""
        target = np.asarray(target_xyz, dtype=float)
        if not self.targets or self.radius_m <= 0:
            return np.zeros(len(target), bool)
        F = np.array([t for _, t in self.targets])
        d = np.linalg.norm(target[:, None, :dim] - F[None, :, :dim], axis=2)
        return np.any(d <= self.radius_m, axis=1)
