"""Search for the object when the estimate has lost it (ROS-free; world frame, metres).

When every touch so far has missed, the free-space observations lift the GP
mean μ above zero over the whole lattice (the kernel's length scale spreads
each one far): the zero level set of μ, and with it every touch candidate, is
gone, although the object is still in the workspace. The run used to stop
there (``no_candidates``), e.g. after two probes into the empty inner corner of
an L-shaped section, or over the hole of a torus.

The search field ``s = μ − β σ`` is negative on the nodes where the object is
most probable: P(inside) = Φ(−μ/σ) is monotone in μ/σ, and β is the
``quantile`` of μ/σ over the lattice, so s < 0 on that fraction of the nodes
(in 3D only nodes at or above ``min_z_m`` count). The search candidates are
the zero crossings of s on lattice edges (used only when the object is lost:
:func:`object_lost`), with the outward normal ∇s/|∇s|
(towards the less probable side: a touch approaches along −∇s, into the most
probable region); the planner plans on the lattice with s in place of μ (its
clearance and free-space graph follow the search surface). A miss lowers σ
and raises μ where it probed, so the search moves on; the first contact
brings back a zero level set of μ, and the ordinary candidates.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Optional

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from .maps import Candidates, MapLattice


def object_lost(lattice: MapLattice, min_z_m: float = -np.inf) -> bool:
    """True when no lattice node is estimated inside (μ < 0; in 3D at or above ``min_z_m``)."""
    mu = lattice.mean_m
    if lattice.dim == 3 and np.isfinite(min_z_m):
        mu = mu[:, :, lattice.axes[2] >= min_z_m]
    return not bool((mu < 0).any())


def search_field(lattice: MapLattice, quantile: float, min_z_m: float = -np.inf) -> np.ndarray:
    """s = μ − β σ on the lattice (lattice shape, m), β = the ``quantile`` of μ/σ over the nodes
    (in 3D those with z ≥ ``min_z_m``)."""
    if not 0.0 < quantile < 1.0:
        raise ValueError(f"search quantile must be in (0, 1), got {quantile}")
    mu = lattice.mean_m
    sigma = np.sqrt(np.maximum(lattice.variance_m2, 1e-300))
    z = mu / sigma
    if lattice.dim == 3 and np.isfinite(min_z_m):
        z = z[:, :, lattice.axes[2] >= min_z_m]
    beta = float(np.quantile(z, quantile))
    return mu - beta * sigma


def _edge_crossings(values: np.ndarray, axes: tuple) -> np.ndarray:
    """Zero crossings of a lattice field on its axis edges, (K, dim), by linear interpolation."""
    pts = []
    for k, ax in enumerate(axes):
        a = [slice(None)] * values.ndim
        b = [slice(None)] * values.ndim
        a[k], b[k] = slice(None, -1), slice(1, None)
        fa, fb = values[tuple(a)], values[tuple(b)]
        idx = np.nonzero((fa < 0) != (fb < 0))
        if not len(idx[0]):
            continue
        t = fa[idx] / (fa[idx] - fb[idx])
        coords = [axes[j][idx[j]] for j in range(values.ndim)]
        coords[k] = coords[k] + t * (ax[1] - ax[0])
        pts.append(np.stack(coords, axis=1))
    return np.concatenate(pts) if pts else np.zeros((0, values.ndim))


def _farthest_points(points: np.ndarray, k: int) -> np.ndarray:
    """Indices of ``k`` points spread over ``points`` (greedy farthest-point order, from the first)."""
    if len(points) <= k:
        return np.arange(len(points))
    chosen = [0]
    d = np.linalg.norm(points - points[0], axis=1)
    for _ in range(k - 1):
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(points - points[i], axis=1))
    return np.array(chosen)


def search_map(lattice: MapLattice, quantile: float, min_z_m: float = -np.inf,
               max_candidates: int = 200) -> Optional[tuple[MapLattice, Candidates]]:
    """The lattice with the search field in place of μ, and candidates on its zero level set
    (at most ``max_candidates``, spread out; their mean and variance are μ and σ² there, so the
    strategies score them by the estimate's own uncertainty). None when s has no zero crossing
    (or, in 3D, none at or above ``min_z_m``)."""
    s = search_field(lattice, quantile, min_z_m)
    pts = _edge_crossings(s, lattice.axes)
    if lattice.dim == 3:
        pts = pts[pts[:, 2] >= min_z_m]
    if not len(pts):
        return None
    pts = pts[_farthest_points(pts, int(max_candidates))]
    interp = lambda field: RegularGridInterpolator(lattice.axes, field)(pts)  # noqa: E731
    grad = np.column_stack([interp(g) for g in np.gradient(s, *lattice.axes)])
    norm = np.linalg.norm(grad, axis=1, keepdims=True)
    normal = np.divide(grad, norm, out=np.zeros_like(grad), where=norm > 1e-12)
    xyz = np.zeros((len(pts), 3))
    xyz[:, : lattice.dim] = pts
    normal3 = np.zeros((len(pts), 3))
    normal3[:, : lattice.dim] = normal
    if lattice.dim == 2:
        xyz[:, 2] = lattice.plane_z_m
    cands = Candidates(xyz=xyz, normal=normal3, mean_m=interp(lattice.mean_m),
                       variance_m2=np.maximum(interp(lattice.variance_m2), 0.0))
    return replace(lattice, mean_m=s), cands
