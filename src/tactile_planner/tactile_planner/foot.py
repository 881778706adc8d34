"""Probes at the foot of a wall (3D): where the estimated wall stops above what the finger can reach.

An object on the table reaches the table. Contacts on a wall (horizontal normals) made high up
leave the GP closing the solid a centimetre or two below the lowest of them, in a bulge whose
underside faces down: the vertical finger cannot touch it ("facing down"), so nothing brings the
estimate down, and later touches climb down the wall a few millimetres at a time (on a generated
letter prism 9 cm tall, 80 touches all landed above 4.2 cm; docs/exploration.md). A foot probe asks
the question directly, at the lowest probe height: is the wall still there?

For a candidate c on a wall (|n_z| ≤ ``wall_max_nz``, horizontal unit normal h), the column
``inset_m`` inside it (c_xy − inset·h) is read down from c's height on the lattice mean (bilinear
in x, y, at the lattice's z nodes): the wall's estimate ends at z_b, the lowest node of the inside
run below c. When z_b lies more than ``gap_m`` above the probe height z_p, a horizontal probe at
z_p goes along −h towards the wall's line. Its target is ``end_offset_m`` outside that line (the
planner sets the offset so that the approach ends with the finger's rod its radius and gap outside
the line: where the wall does not continue, as under an overhang, the rod must not go under the
estimate above); a continuing wall is met just before the approach ends. The probe's mean and
variance are the estimate's at the wall's line at z_p (trilinear), the point the probe tests.
One probe per lattice column of targets (the first candidate's); world frame, metres.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from .maps import Candidates, MapLattice


def _column_means(lattice: MapLattice, q_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q, nz) lattice mean at every z node of the columns through (Q, 2) points (bilinear in x, y),
    and whether each point lies within the lattice's x, y extent."""
    ax, ay = lattice.axes[0], lattice.axes[1]
    inside = (q_xy[:, 0] >= ax[0]) & (q_xy[:, 0] <= ax[-1]) & (q_xy[:, 1] >= ay[0]) & (q_xy[:, 1] <= ay[-1])
    fx = (q_xy[:, 0] - ax[0]) / (ax[1] - ax[0])
    fy = (q_xy[:, 1] - ay[0]) / (ay[1] - ay[0])
    i = np.clip(np.floor(fx).astype(np.int64), 0, len(ax) - 2)
    j = np.clip(np.floor(fy).astype(np.int64), 0, len(ay) - 2)
    t = np.clip(fx - i, 0.0, 1.0)[:, None]
    u = np.clip(fy - j, 0.0, 1.0)[:, None]
    m = lattice.mean_m
    col = ((1 - t) * (1 - u) * m[i, j] + t * (1 - u) * m[i + 1, j]
           + (1 - t) * u * m[i, j + 1] + t * u * m[i + 1, j + 1])
    return col, inside


def foot_probes(lattice: MapLattice, cands: Candidates, probe_z_m: float, gap_m: float, end_offset_m: float,
                inset_m: float = 0.003, wall_max_nz: float = 0.25
                ) -> Optional[tuple[Candidates, np.ndarray, np.ndarray]]:
    """The foot probes of the candidates' walls (module docstring): (probes, the index of the wall
    candidate each comes from, z_b of that wall (m)), or None (2D, or no wall ends that high)."""
    if lattice.dim != 3 or not len(cands):
        return None
    xyz, n = np.asarray(cands.xyz, float), np.asarray(cands.normal, float)
    nh = np.linalg.norm(n[:, :2], axis=1)
    ok = np.isfinite(xyz).all(axis=1) & np.isfinite(n).all(axis=1) & (nh > 1e-9)
    nn = np.linalg.norm(n, axis=1)
    wall = ok & (np.abs(n[:, 2]) <= wall_max_nz * np.where(ok, nn, 1.0)) & (xyz[:, 2] > probe_z_m + gap_m)
    idx = np.flatnonzero(wall)
    if not len(idx):
        return None
    h = n[idx, :2] / nh[idx, None]
    col, in_xy = _column_means(lattice, xyz[idx, :2] - inset_m * h)
    z = lattice.axes[2]
    k0 = np.clip(np.floor((xyz[idx, 2] - z[0]) / (z[1] - z[0])).astype(np.int64), 0, len(z) - 1)
    rows = np.arange(len(idx))
    inside = col < 0
    # the lowest node of the inside run from k0 down: one above the highest outside node at or below k0
    out_below = ~inside & (np.arange(len(z))[None, :] <= k0[:, None])
    last_out = np.where(out_below.any(axis=1), len(z) - 1 - np.argmax(out_below[:, ::-1], axis=1), -1)
    z_b = z[np.clip(last_out + 1, 0, len(z) - 1)]
    keep = in_xy & inside[rows, k0] & (z_b > probe_z_m + gap_m)  # inside at c's height: the run starts there
    if not keep.any():
        return None
    idx, h, z_b = idx[keep], h[keep], z_b[keep]
    line = np.column_stack([xyz[idx, :2], np.full(len(idx), probe_z_m)])  # the wall's line at the probe height
    target = line.copy()
    target[:, :2] += end_offset_m * h
    cell = np.rint((target[:, :2] - lattice.origin[:2]) / lattice.spacing_m[:2]).astype(np.int64)
    _, first = np.unique(cell, axis=0, return_index=True)
    first = np.sort(first)
    idx, h, z_b, line, target = idx[first], h[first], z_b[first], line[first], target[first]
    mean, var = (RegularGridInterpolator(lattice.axes, f, bounds_error=False, fill_value=None)(line)
                 for f in (lattice.mean_m, lattice.variance_m2))
    probes = Candidates(xyz=target, normal=np.column_stack([h, np.zeros(len(idx))]), mean_m=mean,
                        variance_m2=np.maximum(var, 0.0))
    return probes, idx, z_b
