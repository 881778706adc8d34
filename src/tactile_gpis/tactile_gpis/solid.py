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
    boxes = ndimage.find_objects(labels)
    low = np.array([box[2].start for box in boxes], dtype=int)
    floating = np.r_[False, (np.asarray(axes[2])[low] - axes[2][0]) > floating_gap_m]
    if not floating.any():
        return out
    touched = np.zeros(n + 1, bool)
    c = np.asarray(contacts_xyz, float).reshape(-1, 3)
    if len(c):
        origin = np.array([a[0] for a in axes])
        spacing = np.array([a[1] - a[0] for a in axes])
        reach = float(np.linalg.norm(spacing))  # a contact lies on its component's surface: within a cell
        c = c[_near_boxes(c, boxes, floating, origin, spacing, reach)]
        k = int(np.ceil(reach / spacing.min()))
        offs = np.array(list(itertools.product(range(-k, k + 1), repeat=3)))  # (K, 3)
        shape = np.array(inside.shape)
        # in chunks, stopping once every floating component is touched: thousands of contacts on a
        # floating component cost one chunk, not C × K lookups
        for i in range(0, len(c), _CHUNK):
            ci = c[i:i + _CHUNK]
            idx = np.rint((ci - origin) / spacing).astype(np.int64)[:, None, :] + offs[None, :, :]  # (C, K, 3)
            ok = np.all((idx >= 0) & (idx < shape), axis=2)
            idx = np.clip(idx, 0, shape - 1)
            ok &= np.linalg.norm(origin + idx * spacing - ci[:, None, :], axis=2) <= reach
            touched[labels[idx[..., 0], idx[..., 1], idx[..., 2]][ok]] = True
            if touched[floating].all():
                break
    drop = floating & ~touched
    drop[0] = False
    return drop[labels] if drop.any() else out


#: contacts per vectorised neighbourhood lookup in :func:`floating_untouched` (C × 125 nodes each)
_CHUNK = 64


def _near_boxes(c: np.ndarray, boxes: list, floating: np.ndarray, origin: np.ndarray, spacing: np.ndarray,
                reach: float) -> np.ndarray:
    """Bool per contact: within ``reach`` of the bounding box of a floating component (``floating`` is
    indexed by label, 0 the background; ``boxes`` by label − 1). Only those can touch one."""
    fl = np.flatnonzero(floating[1:])
    lo = np.array([[b.start for b in boxes[j]] for j in fl]) * spacing + origin - reach  # (F, 3)
    hi = np.array([[b.stop - 1 for b in boxes[j]] for j in fl]) * spacing + origin + reach
    return np.any(np.all((c[:, None, :] >= lo[None]) & (c[:, None, :] <= hi[None]), axis=2), axis=1)
