"""The wrist beyond the flange kept clear by a tilted finger (3D): the table and the estimate.

The rod is thin, the arm's last links behind the flange are not: cylinders about the finger axis
(:mod:`tactile_common.wrist`: the bands, the Panda's by default). A vertical finger carries them 16 cm
and more above its tip, over any object lower than that (they are not checked for a vertical finger:
beside an object taller than the rod they would not be clear); a tilted one brings them down towards
the table and the object, which the flange-height rule alone (``tilt_min_flange_z_m``) does not see:
level, with the flange 10 cm up, link 6 would reach 4 cm into the table.

World frame, metres. A pose (tip centre x, finger axis a) is clear when

- the table: the cylinders' lowest point (:func:`tactile_common.wrist.wrist_lowest_z_m`) is at or
  above ``floor_z_m`` (the planner's table + table margin);
- the estimate: every lattice node on the estimate's boundary (μ < 0 with a 6-neighbour μ ≥ 0) lies at
  least ``gap_m`` + the lattice's half cell diagonal (the estimated surface may lie that far past a
  node) from each cylinder (exact point-to-cylinder distance, for the nodes a k-d tree finds near it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.spatial import cKDTree

from tactile_common.wrist import PANDA_WRIST_BANDS_M, bands_from_flat, wrist_lowest_z_m

__all__ = ["PANDA_WRIST_BANDS_M", "WristCheck", "band_points", "bands_from_flat"]


def band_points(tip_xyz: np.ndarray, axis_xyz: np.ndarray, bands_m: tuple, rod_length_m: float,
                step_m: float = 0.01, n_phi: int = 24) -> np.ndarray:
    """(N, P, 3) points on the wrist's cylinders of N poses (world): on each band's axis and rim every
    ``step_m`` along it (both ends included) and on its two end discs at half the radius, ``n_phi``
    around: for measuring the wrist against an exact object (a sample, not a bound)."""
    x = np.asarray(tip_xyz, float).reshape(-1, 3)
    a = np.broadcast_to(np.asarray(axis_xyz, float).reshape(-1, 3), x.shape)
    u = np.cross(a, np.where(np.abs(a[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(a, u)
    phi = np.linspace(0.0, 2.0 * np.pi, n_phi, endpoint=False)
    out = []
    for t0, t1, rho in bands_m:
        t = rod_length_m + np.append(np.arange(t0, t1, step_m), t1)
        ends = rod_length_m + np.array([t0, t1])
        # (t, radius) pairs: the axis and the rim along the band, half the radius on the end discs
        tr = np.concatenate([np.column_stack([np.repeat(t, n_phi), np.full(len(t) * n_phi, rho)]),
                             np.column_stack([np.repeat(ends, n_phi), np.full(2 * n_phi, 0.5 * rho)]),
                             np.column_stack([t, np.zeros(len(t))])])
        ang = np.concatenate([np.tile(phi, len(t)), np.tile(phi, 2), np.zeros(len(t))])
        off = ((tr[:, 1] * np.cos(ang))[None, :, None] * u[:, None, :]
               + (tr[:, 1] * np.sin(ang))[None, :, None] * v[:, None, :])
        out.append(x[:, None, :] + tr[None, :, 0, None] * a[:, None, :] + off)
    return np.concatenate(out, axis=1)


@dataclass(frozen=True)
class WristCheck:
    """Clearance of the wrist's bands from the table and from an estimate (module docstring)."""

    bands_m: tuple
    rod_length_m: float
    floor_z_m: float
    gap_m: float
    slack_m: float  # half the lattice's cell diagonal
    boundary: Optional[cKDTree]  # the estimate's boundary nodes (None: none)

    @classmethod
    def on_lattice(cls, lattice, bands_m: tuple, rod_length_m: float, floor_z_m: float,
                   gap_m: float) -> "WristCheck":
        """The check against the lattice mean of a 3D estimate (nodes with μ < 0 are inside)."""
        inside = np.asarray(lattice.mean_m) < 0
        edge = np.zeros_like(inside)
        for k in range(inside.ndim):  # an inside node with an outside neighbour along some axis
            lo, hi = [slice(None)] * inside.ndim, [slice(None)] * inside.ndim
            lo[k], hi[k] = slice(None, -1), slice(1, None)
            differ = inside[tuple(lo)] != inside[tuple(hi)]
            edge[tuple(lo)] |= differ & inside[tuple(lo)]
            edge[tuple(hi)] |= differ & inside[tuple(hi)]
        nodes = lattice.grid_xyz()[edge.ravel()]
        tree = cKDTree(nodes[:, :3]) if len(nodes) else None
        slack = 0.5 * float(np.linalg.norm(lattice.spacing_m))
        return cls(tuple(bands_m), float(rod_length_m), float(floor_z_m), float(gap_m), slack, tree)

    def clear(self, tip_xyz: np.ndarray, axis_xyz: np.ndarray) -> np.ndarray:
        """(N,) bool: the wrist of the finger at (N, 3) tip centres with (3,) or (N, 3) unit axes is clear."""
        x = np.asarray(tip_xyz, float).reshape(-1, 3)
        a = np.broadcast_to(np.asarray(axis_xyz, float).reshape(-1, 3), x.shape)
        ok = np.ones(len(x), bool)
        if not len(x):
            return ok
        ok &= wrist_lowest_z_m(x, a, self.bands_m, self.rod_length_m) >= self.floor_z_m - 1e-12
        if self.boundary is not None:
            need = self.gap_m + self.slack_m
            for t0, t1, rho in self.bands_m:
                ok &= self._off_estimate(x, a, t0, t1, rho, need)
        return ok

    def _off_estimate(self, x: np.ndarray, a: np.ndarray, t0: float, t1: float, rho: float,
                      need: float) -> np.ndarray:
        """(N,) bool: no boundary node within ``need`` of the band's cylinder (exact distance)."""
        half = 0.5 * (t1 - t0)
        centre = x + (self.rod_length_m + t0 + half) * a
        near = self.boundary.query_ball_point(centre, float(np.hypot(rho + need, half + need)))
        counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=len(near))
        ok = np.ones(len(x), bool)
        if not counts.sum():
            return ok
        row = np.repeat(np.arange(len(x)), counts)
        d = self.boundary.data[np.concatenate([n for n in near if n])] - centre[row]
        u = np.einsum("ij,ij->i", d, a[row])
        r = np.linalg.norm(d - u[:, None] * a[row], axis=1)
        dist = np.hypot(np.maximum(np.abs(u) - half, 0.0), np.maximum(r - rho, 0.0))
        ok[np.unique(row[dist < need])] = False
        return ok
