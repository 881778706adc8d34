"""Free-space lattice graph around the estimated object (world frame, metres).

A lattice node is free when the GP mean (≈ signed distance, metres) is at least
``margin_m`` (optionally also P(inside) = Φ(−μ/σ) ≤ ``p_inside_max``), in 3D
when its height is at least ``min_z_m``, and with ``shell_m > 0`` when μ ≤
margin + shell (a band/shell around the surface: the graph grows with the
surface, not the workspace). Edges join 8 (2D) / 26 (3D) neighbours and exist only when every
lattice node of the box spanned by the edge is free, so the multilinear
interpolation of μ along an edge never drops below the margin.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import RegularGridInterpolator
from scipy.special import ndtr

from .maps import MapLattice


@dataclass
class FreeSpaceGraph:
    """Free lattice nodes and their edges.

    Attributes:
        lattice: the estimator lattice it was built on.
        free: boolean mask over the lattice (shape = lattice shape).
        node_of_grid: flat lattice index -> graph node (−1 = not free).
        grid_of_node: graph node -> flat lattice index.
        xyz: (N, 3) node positions (m).
        length_m: symmetric CSR (N, N) of edge lengths (m).
        margin_m: the clearance every node keeps from the estimated surface.
    """

    lattice: MapLattice
    free: np.ndarray
    node_of_grid: np.ndarray
    grid_of_node: np.ndarray
    xyz: np.ndarray
    length_m: sp.csr_matrix
    margin_m: float
    min_z_m: float

    @property
    def n_nodes(self) -> int:
        return int(self.xyz.shape[0])

    def nearest_node(self, p_xyz: np.ndarray) -> int:
        """Free node closest (Euclidean) to one point; −1 when there is none."""
        if self.n_nodes == 0:
            return -1
        d2 = np.sum((self.xyz - np.asarray(p_xyz, float)[None, :]) ** 2, axis=1)
        return int(np.argmin(d2))

    def attach(self, p_xyz: np.ndarray, reach: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """Nearest free node to each point among lattice nodes within ``reach`` cells.

        Args:
            p_xyz: (M, 3) points.
        Returns:
            node (M,) (−1 if none in reach) and distance (M,) in metres (inf if none).
        """
        lat = self.lattice
        d = lat.dim
        p = np.asarray(p_xyz, float).reshape(-1, 3)[:, :d]
        base = np.rint((p - lat.origin) / lat.spacing_m).astype(np.int64)  # (M, d)
        offs = np.array(list(itertools.product(range(-reach, reach + 1), repeat=d)))  # (K, d)
        idx = base[:, None, :] + offs[None, :, :]  # (M, K, d)
        shape = np.array(lat.shape)
        inside = np.all((idx >= 0) & (idx < shape), axis=2)
        flat = np.ravel_multi_index(tuple(np.clip(idx, 0, shape - 1).transpose(2, 0, 1)), lat.shape)
        node = np.where(inside, self.node_of_grid[flat], -1)
        pos = np.take(self.xyz, np.maximum(node, 0), axis=0)  # (M, K, 3)
        full = np.asarray(p_xyz, float).reshape(-1, 3)
        dist = np.linalg.norm(pos - full[:, None, :], axis=2)
        dist = np.where(node >= 0, dist, np.inf)
        k = np.argmin(dist, axis=1)
        rows = np.arange(len(p))
        best = node[rows, k]
        bd = dist[rows, k]
        best = np.where(np.isfinite(bd), best, -1)
        return best, bd

    def clearance_m(self, p_xyz: np.ndarray) -> np.ndarray:
        """Multilinear interpolation of μ at points (+inf outside the lattice: the object lies
        inside the estimator's workspace box; −inf below min z in 3D)."""
        lat = self.lattice
        p = np.asarray(p_xyz, float).reshape(-1, 3)
        interp = RegularGridInterpolator(lat.axes, lat.mean_m, bounds_error=False, fill_value=np.inf)
        mu = interp(p[:, : lat.dim])
        if lat.dim == 3:
            mu = np.where(p[:, 2] >= self.min_z_m - 1e-12, mu, -np.inf)
        return mu

    def segments_free(self, a_xyz: np.ndarray, b_xyz: np.ndarray, step_m: float | None = None) -> np.ndarray:
        """For each segment a→b ((S, 3) each), whether all samples keep μ ≥ margin."""
        a = np.asarray(a_xyz, float).reshape(-1, 3)
        b = np.asarray(b_xyz, float).reshape(-1, 3)
        step = step_m if step_m is not None else float(np.min(self.lattice.spacing_m)) / 4.0
        n = int(np.ceil(np.max(np.linalg.norm(b - a, axis=1), initial=0.0) / step)) + 1
        t = np.linspace(0.0, 1.0, max(n, 2))
        pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
        mu = self.clearance_m(pts.reshape(-1, 3)).reshape(len(a), -1)
        return np.all(mu >= self.margin_m - 1e-9, axis=1)


def _view(padded: np.ndarray, off: tuple, shape: tuple) -> np.ndarray:
    """``padded`` (padded by 1) shifted by ``off``: value at lattice index a + off."""
    return padded[tuple(slice(1 + o, 1 + o + n) for o, n in zip(off, shape))]


def build_free_graph(
    lattice: MapLattice,
    margin_m: float,
    shell_m: float = 0.0,
    min_z_m: float = -np.inf,
    p_inside_max: float | None = None,
) -> FreeSpaceGraph:
    """Free-space graph of a lattice (see the module docstring for the rules).

    Args:
        lattice: estimator lattice with the GP mean/variance.
        margin_m: minimum μ (≈ distance of the tip centre from the estimated surface).
        shell_m: keep only nodes with μ ≤ margin + shell (0 = all free space).
        min_z_m: 3D only: lowest allowed node height (table + margin + tip radius).
        p_inside_max: if set, also drop nodes with Φ(−μ/σ) above it.
    """
    mu = lattice.mean_m
    free = mu >= margin_m
    if p_inside_max is not None:
        sigma = np.sqrt(np.maximum(lattice.variance_m2, 1e-300))
        free &= ndtr(-mu / sigma) <= p_inside_max
    if lattice.dim == 3:
        free &= (lattice.axes[2] >= min_z_m)[None, None, :]
    if shell_m > 0:
        free &= mu <= margin_m + shell_m
    shape = lattice.shape
    d = lattice.dim
    node_of_grid = np.full(free.size, -1, dtype=np.int64)
    grid_of_node = np.flatnonzero(free.ravel())
    node_of_grid[grid_of_node] = np.arange(len(grid_of_node))
    xyz = lattice.grid_xyz()[grid_of_node]
    padded = np.pad(free, 1, constant_values=False)
    strides = np.array([int(np.prod(shape[k + 1:])) for k in range(d)])
    spacing = lattice.spacing_m
    rows, cols, lens = [], [], []
    for off in itertools.product((-1, 0, 1), repeat=d):
        if off <= (0,) * d:  # each undirected edge once: lexicographically positive offsets
            continue
        box = free.copy()
        for sub in itertools.product(*[(0, o) if o else (0,) for o in off]):
            if any(sub):
                box &= _view(padded, sub, shape)
        src = np.flatnonzero(box.ravel())
        dst = src + int(np.dot(off, strides))
        rows.append(node_of_grid[src])
        cols.append(node_of_grid[dst])
        lens.append(np.full(len(src), float(np.linalg.norm(np.array(off) * spacing))))
    r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    ln = np.concatenate(lens) if lens else np.zeros(0)
    n = len(grid_of_node)
    length = sp.coo_matrix(
        (np.concatenate([ln, ln]), (np.concatenate([r, c]), np.concatenate([c, r]))), shape=(n, n)
    ).tocsr()
    return FreeSpaceGraph(
        lattice=lattice, free=free, node_of_grid=node_of_grid, grid_of_node=grid_of_node,
        xyz=xyz, length_m=length, margin_m=float(margin_m),
        min_z_m=float(min_z_m) if lattice.dim == 3 else -np.inf,
    )
