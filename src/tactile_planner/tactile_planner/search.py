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

from .graph import edge_zero_crossings
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
    pts = edge_zero_crossings(s, lattice.axes)
    if lattice.dim == 3:
        pts = pts[pts[:, 2] >= min_z_m]
    if not len(pts):
        return None
    pts = pts[_farthest_points(pts, int(max_candidates))]
    grad = np.column_stack([RegularGridInterpolator(lattice.axes, g)(pts) for g in np.gradient(s, *lattice.axes)])
    norm = np.linalg.norm(grad, axis=1, keepdims=True)
    normal = np.divide(grad, norm, out=np.zeros_like(grad), where=norm > 1e-12)
    return _searching(lattice, s, pts, normal)


def _searching(lattice: MapLattice, field_m: np.ndarray, pts: np.ndarray,
               normals: np.ndarray) -> tuple[MapLattice, Candidates]:
    """The lattice with ``field_m`` in place of μ, and candidates at ``pts`` (K, dim) with unit
    ``normals`` (K, dim), carrying the estimate's μ and σ² there (2D: at the plane height)."""
    interp = lambda field: RegularGridInterpolator(lattice.axes, field)(pts)  # noqa: E731
    xyz = np.zeros((len(pts), 3))
    xyz[:, : lattice.dim] = pts
    normal3 = np.zeros((len(pts), 3))
    normal3[:, : lattice.dim] = normals
    if lattice.dim == 2:
        xyz[:, 2] = lattice.plane_z_m
    cands = Candidates(xyz=xyz, normal=normal3, mean_m=interp(lattice.mean_m),
                       variance_m2=np.maximum(interp(lattice.variance_m2), 0.0))
    return replace(lattice, mean_m=field_m), cands


def ring_radii_m(lattice: MapLattice, step_m: float, first_m: Optional[float] = None) -> list[float]:
    """Radii of the coverage rings around :func:`ring_centre` (m), in the order they are searched:
    ``first_m`` (default a quarter of the smallest horizontal extent, the size of an object the
    workspace is made for), then alternately ``step_m`` further in and out, down to ``step_m / 2``
    and up to the farthest lattice corner."""
    if not step_m > 0:
        raise ValueError(f"ring step must be positive, got {step_m}")
    lo, hi = np.array([a[0] for a in lattice.axes]), np.array([a[-1] for a in lattice.axes])
    r0 = 0.25 * float(np.min((hi - lo)[:2])) if first_m is None else float(first_m)
    c = ring_centre(lattice)[: lattice.dim]
    far = float(np.max(np.linalg.norm(np.array(np.meshgrid(*zip(lo, hi))).reshape(lattice.dim, -1).T - c, axis=1)))
    radii, k = [r0], 1
    while True:
        inner, outer = r0 - k * step_m, r0 + k * step_m
        if inner < 0.5 * step_m and outer > far:
            return radii
        radii += [r for r in (inner, outer) if 0.5 * step_m <= r <= far]
        k += 1


def ring_centre(lattice: MapLattice) -> np.ndarray:
    """Centre of the coverage rings: the middle of the lattice (3D: on its floor, the table), world."""
    c = np.array([0.5 * (a[0] + a[-1]) for a in lattice.axes] + [0.0] * (3 - lattice.dim))
    if lattice.dim == 3:
        c[2] = lattice.axes[2][0]
    else:
        c[2] = lattice.plane_z_m
    return c


def _ring_points(dim: int, radius_m: float, spacing_m: float, flat: bool = False) -> np.ndarray:
    """Unit directions about ``spacing_m`` apart on a circle (2D; 3D with ``flat``: horizontal, z = 0) or
    an upper hemisphere (3D, Fibonacci lattice), (K, dim)."""
    if dim == 2 or flat:
        k = max(3, int(np.ceil(2 * np.pi * radius_m / spacing_m)))
        a = 2 * np.pi * np.arange(k) / k
        return np.column_stack([np.cos(a), np.sin(a)] + [np.zeros(k)] * (dim - 2))
    k = max(4, int(np.ceil(2 * np.pi * radius_m ** 2 / spacing_m ** 2)))  # hemisphere area / spacing²
    i = np.arange(k) + 0.5
    z = i / k  # uniform in z on (0, 1]: uniform in area on the hemisphere
    phi = np.pi * (1 + 5 ** 0.5) * i
    rho = np.sqrt(1 - z ** 2)
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


def floating_base(lattice: MapLattice, min_z_m: float, gap_m: float) -> Optional[tuple[np.ndarray, float, float]]:
    """3D: an estimated solid that does not reach the table, whose lowest node estimated inside
    (μ < 0, at or above ``min_z_m``) lies more than ``gap_m`` above the lattice floor (the table).
    An object on the table reaches the table, so such an estimate is missing what holds it up
    (a bridge's pillars under its deck). Returns (the footprint's centre (3,) on the floor, its
    radius (m): the farthest inside node from that centre, horizontally; the lowest inside z), or
    None (2D, no inside node, or the estimate reaches down to the floor)."""
    if lattice.dim != 3:
        return None
    i, j, k = np.nonzero((lattice.mean_m < 0) & (lattice.axes[2] >= min_z_m)[None, None, :])
    if not len(k):
        return None
    floor = float(lattice.axes[2][0])
    z_low = float(lattice.axes[2][k.min()])
    if z_low - floor <= gap_m:
        return None
    x, y = lattice.axes[0][i], lattice.axes[1][j]
    centre = np.array([0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max()), floor])
    radius = float(np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2).max())
    return centre, radius, z_low


def ring_search_map(lattice: MapLattice, radius_m: float, spacing_m: float, min_z_m: float = -np.inf,
                    inset_m: float = 0.0, centre_xyz: Optional[np.ndarray] = None,
                    max_z_m: float = np.inf, table_z_m: Optional[float] = None,
                    cap_above_m: float = np.inf) -> Optional[tuple[MapLattice, Candidates]]:
    """The coverage search of one ring: the lattice with s = |x − c| − r in place of μ (paths keep
    off the ring) and candidates ``spacing_m`` apart on it, normals pointing away from the centre c
    (:func:`ring_centre`), so each probe sweeps the ring's width towards the centre.

    Used when the object is lost and the probability search (:func:`search_map`) has nothing left
    to probe: the GP's mean far from every observation is the prior's shape plus the kernel's
    extrapolation, not evidence, so the rings cover the workspace instead, ring after ring
    (:func:`ring_radii_m`). Candidates farther than ``inset_m`` inside the lattice only (3D: at or
    above ``min_z_m`` and below ``max_z_m``); their mean and variance are the estimate's (μ, σ²), so
    the strategies prefer the unexplored parts of the ring (high σ) near the tip. ``centre_xyz``:
    another centre than the workspace's (a floating estimate's footprint, :func:`floating_base`).

    3D with ``table_z_m``: the ring is the horizontal circle at that height (the lowest probe height),
    approached level towards the centre, and s = the signed distance to the solid cylinder through it,
    from the table up to ``cap_above_m`` above the ring (its top; default none: an infinite
    cylinder). Paths keep off the ring at the probe height and may cross above it: a tip left inside
    the ring by a probe that missed leaves it over the top, not by the lattice's top. An
    object stands on the table, so its footprint crosses the height every object reaches; a circle
    needs 2πr/spacing probes where the hemisphere needs 2πr²/spacing² (24 against 88 at r = 7.5 cm),
    and it finds a flat object that the hemisphere's probes pass over.

    None when no point is left."""
    c = ring_centre(lattice) if centre_xyz is None else np.asarray(centre_xyz, dtype=float).reshape(3)
    flat = lattice.dim == 3 and table_z_m is not None
    dirs = _ring_points(lattice.dim, radius_m, spacing_m, flat)
    pts = c[: lattice.dim] + radius_m * dirs
    if flat:
        pts[:, 2] = table_z_m
    lo = np.array([a[0] for a in lattice.axes]) + inset_m
    hi = np.array([a[-1] for a in lattice.axes]) - inset_m
    on_lattice = (pts >= lo) & (pts <= hi)
    keep = np.all(on_lattice[:, :2] if flat else on_lattice, axis=1)  # a level probe's pre-touch: x, y only
    if lattice.dim == 3:
        keep &= (pts[:, 2] >= min_z_m) & (pts[:, 2] < max_z_m)
    pts, dirs = pts[keep], dirs[keep]
    if not len(pts):
        return None
    grids = np.meshgrid(*lattice.axes, indexing="ij")
    s = np.sqrt(sum((g - c[k]) ** 2 for k, g in enumerate(grids[:2] if flat else grids))) - radius_m
    if flat and np.isfinite(cap_above_m):
        above_m = grids[2] - (table_z_m + cap_above_m)  # signed distance to the top's plane
        s = np.where((s > 0) & (above_m > 0), np.hypot(s, above_m), np.maximum(s, above_m))
    return _searching(lattice, s, pts, dirs)
