"""The estimated solid in 3D: the parts of {μ < 0} that the data holds up.

With the thin-plate kernel every observation reaches across the whole workspace, so far from the
data the posterior mean is the prior plus a smooth correction that can hover near zero; a new
contact can then tip a region centimetres from any data below zero (a thin wall's run grew a
3 × 3 × 1.4 cm blob at the workspace's top, 13 cm above the object, and its IoU fell 0.88 → 0.78).
The object is one rigid body resting on the table, so a connected component of {μ < 0} that no
contact touches and whose lowest node floats above the table is not part of it: no observation
says it is there. :func:`floating_untouched` finds those components on the estimator's lattice
(world frame, metres; z the last axis, the table at the lattice's lowest layer).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage


def floating_untouched(mean_m: np.ndarray, axes: list[np.ndarray], contacts_xyz: np.ndarray,
                       floating_gap_m: float) -> np.ndarray:
    """Bool (lattice shape): the nodes of the components of {μ < 0} (26-connected) that hold no node
    within one lattice-cell diagonal of a contact and whose lowest node is more than
    ``floating_gap_m`` above the lattice's lowest layer (the table).

    Args:
        mean_m: the lattice mean μ (3D lattice shape, m; < 0 inside).
        axes: the three lattice axes (ascending, evenly spaced, m).
        contacts_xyz: (C, 3) contact points (m).
        floating_gap_m: how far above the table a component's lowest node must be to float (m).
    """
    inside = np.asarray(mean_m) < 0
    out = np.zeros(inside.shape, bool)
    if not inside.any():
        return out
    labels, n = ndimage.label(inside, structure=np.ones((3, 3, 3), bool))
    # lowest node of each component: where its bounding box starts along z
    low = np.array([box[2].start for box in ndimage.find_objects(labels)], dtype=int)
    floating = np.r_[False, (np.asarray(axes[2])[low] - axes[2][0]) > floating_gap_m]
    if not floating.any():
        return out
    touched = np.zeros(n + 1, bool)
    c = np.asarray(contacts_xyz, float).reshape(-1, 3)
    if len(c):
        origin = np.array([a[0] for a in axes])
        spacing = np.array([a[1] - a[0] for a in axes])
        reach = float(np.linalg.norm(spacing))  # a contact lies on its component's surface: within a cell
        k = int(np.ceil(reach / spacing.min()))
        offs = np.array(list(itertools.product(range(-k, k + 1), repeat=3)))  # (K, 3)
        base = np.rint((c - origin) / spacing).astype(np.int64)
        idx = base[:, None, :] + offs[None, :, :]  # (C, K, 3)
        shape = np.array(inside.shape)
        ok = np.all((idx >= 0) & (idx < shape), axis=2)
        idx = np.clip(idx, 0, shape - 1)
        pos = origin + idx * spacing
        ok &= np.linalg.norm(pos - c[:, None, :], axis=2) <= reach
        touched[labels[idx[..., 0], idx[..., 1], idx[..., 2]][ok]] = True
    drop = floating & ~touched
    drop[0] = False
    return drop[labels]
