"""Free-space lattice graph around the estimated object (world frame, metres).

Clearance c(x) of the tip centre from the estimated object, on the lattice:

- ``clearance="distance"`` (the planner's default): the signed Euclidean
  distance to the estimated surface, the zero level set of the GP mean μ
  (|c| = distance to the nearest zero crossing of μ on a lattice edge, found
  by linear interpolation; sign of μ). Exact up to O(h²/d) for lattice step h
  at distance d (≤ 0.1 mm at 15 mm on a 2.4 mm lattice).
- ``clearance="mean"``: μ itself. μ is a signed distance only where
  |∇μ| ≈ 1, i.e. near contacts with normals; where the estimate is uncertain
  the GP mean is flatter (|∇μ| < 1) and μ underestimates the distance, so a
  pre-touch point placed at a fixed distance along the normal falls inside
  the margin exactly on the parts of the surface the estimate has not
  confirmed (docs/exploration.md, "Why the planner stalled"). The planner
  therefore measures a candidate's last segment, whatever the clearance, by
  :meth:`FreeSpaceGraph.surface_distance_at`.

A lattice node is free when c ≥ ``margin_m`` (optionally also P(inside) =
Φ(−μ/σ) ≤ ``p_inside_max``), in 3D when its height is at least ``min_z_m``,
and with ``shell_m > 0`` when c ≤ margin + shell (a band/shell around the
surface: the graph grows with the surface, not the workspace). Edges join 8
(2D) / 26 (3D) neighbours and exist only when every lattice node of the box
spanned by the edge is free, so the multilinear interpolation of c along an
edge never drops below the margin.

Narrow nodes (2D, ``narrow_penalty > 0``): a node with the finger's own room,
c ≥ ``finger_m`` (tip radius + a small gap) but c < margin, is free too, and
an edge with such an end counts ``narrow_penalty`` times its length: a slot
the estimate narrows below twice the margin but not below the finger is a
path, at a price, instead of a wall (docs/planner.md). Shortcuts still keep
the margin; a candidate's last segment from a narrow node keeps the finger's
room.

The finger's shaft (3D, ``shaft_length_m > 0``): the finger is a rod that rises
vertically from the tip (the commander keeps it within a few degrees of
vertical), so a tip position is only free when the rod above it clears the
estimated object too. With s(x) = min of c over the lattice nodes above x up to
``shaft_length_m`` (+inf above the lattice: :func:`shaft_column_min`), the
clearance the graph tests becomes min(c, s − ``shaft_clearance_m`` + margin):
a node is free when c ≥ margin and s ≥ ``shaft_clearance_m`` (the rod's radius
plus the tip's skin clearance), so no node, edge or shortcut lies under an
overhang of the estimate. The clearance c itself is kept (``shaft_field_m``) for
the planner's checks of the rod above a tip that meets the surface, sampled
along the rod (:meth:`FreeSpaceGraph.rod_clearance_m`; docs/planner.md, "The
finger's shaft").
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csg
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial import cKDTree
from scipy.special import ndtr

from tactile_common.touch_geometry import rod_points

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
        margin_m: the clearance paths keep from the estimated surface (nodes, shortcuts).
        finger_m: the clearance the narrow nodes keep (``build_free_graph``'s ``narrow_penalty``), below
            ``margin_m``; None without them.
        clearance_field_m: the clearance c on the lattice (lattice shape, m; see the module docstring).
        shaft_field_m, shaft_length_m: 3D with the finger's shaft: the clearance the rod is checked against
            (lattice shape, m: c before the rod's term) and the rod's length; None and 0 without.
    """

    lattice: MapLattice
    free: np.ndarray
    node_of_grid: np.ndarray
    grid_of_node: np.ndarray
    xyz: np.ndarray
    length_m: sp.csr_matrix
    margin_m: float
    min_z_m: float
    clearance_field_m: np.ndarray | None = None
    finger_m: float | None = None
    shaft_field_m: np.ndarray | None = None
    shaft_length_m: float = 0.0
    _crossings: cKDTree | None = field(default=None, init=False, repr=False, compare=False)

    def rod_clearance_m(self, p_xyz: np.ndarray, start_m: float, step_m: float = 0.004,
                        axis_xyz: np.ndarray | None = None, length_m: float | None = None) -> np.ndarray:
        """The estimated clearance of the rod above each (M, 3) tip centre: the minimum of the clearance c
        (multilinear) along the finger axis (``axis_xyz``: (3,) or (M, 3) unit; None = vertical) from
        ``start_m`` to ``length_m`` (default ``shaft_length_m``) past the centre, every ``step_m`` (+inf
        without a shaft; outside the lattice nothing limits)."""
        p = np.asarray(p_xyz, float).reshape(-1, 3)
        if self.shaft_field_m is None:
            return np.full(len(p), np.inf)
        rod = rod_points(p, start_m, self.shaft_length_m if length_m is None else length_m, step_m, axis_xyz)
        return self.shaft_field_at(rod.reshape(-1, 3)).reshape(rod.shape[:2]).min(axis=1)

    def shaft_field_at(self, p_xyz: np.ndarray) -> np.ndarray:
        """The rod's clearance field (multilinear) at (M, 3) points: +inf outside the lattice or without a shaft."""
        p = np.asarray(p_xyz, float).reshape(-1, 3)
        if self.shaft_field_m is None:
            return np.full(len(p), np.inf)
        interp = RegularGridInterpolator(self.lattice.axes, self.shaft_field_m, bounds_error=False,
                                         fill_value=np.inf)
        return interp(p)

    @property
    def n_nodes(self) -> int:
        return int(self.xyz.shape[0])

    def nearest_node(self, p_xyz: np.ndarray) -> int:
        """Free node closest (Euclidean) to one point; −1 when there is none."""
        if self.n_nodes == 0:
            return -1
        d2 = np.sum((self.xyz - np.asarray(p_xyz, float)[None, :]) ** 2, axis=1)
        return int(np.argmin(d2))

    def attach(self, p_xyz: np.ndarray, reach: int = 2,
               allowed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Nearest free node to each point among lattice nodes within ``reach`` cells.

        Args:
            p_xyz: (M, 3) points.
            allowed: optional (N,) bool over the graph's nodes: attach only to those.
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
        if allowed is not None:
            node = np.where((node >= 0) & allowed[np.maximum(node, 0)], node, -1)
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

    @property
    def clearance_lattice_m(self) -> np.ndarray:
        """The clearance c on the lattice nodes (lattice shape, m): the field, or μ with ``clearance="mean"``."""
        return self.lattice.mean_m if self.clearance_field_m is None else self.clearance_field_m

    def clearance_m(self, p_xyz: np.ndarray) -> np.ndarray:
        """Multilinear interpolation of the clearance c at points (+inf outside the lattice: the
        object lies inside the estimator's workspace box; −inf below min z in 3D)."""
        lat = self.lattice
        p = np.asarray(p_xyz, float).reshape(-1, 3)
        interp = RegularGridInterpolator(lat.axes, self.clearance_lattice_m, bounds_error=False, fill_value=np.inf)
        mu = interp(p[:, : lat.dim])
        if lat.dim == 3:
            mu = np.where(p[:, 2] >= self.min_z_m - 1e-12, mu, -np.inf)
        return mu

    def surface_distance_at(self, p_xyz: np.ndarray, max_m: float = np.inf) -> np.ndarray:
        """Signed Euclidean distance (m) from (M, 3) points to the estimate's zero level set: the nearest
        zero crossing of μ on a lattice edge (:func:`zero_crossings_m`, found once per graph), negative
        where the multilinear μ is; −inf below ``min_z_m`` in 3D, ±inf when μ has no crossing.
        Unlike μ it is a distance off the data too, where the GP mean is flatter (|∇μ| < 1). Distances
        beyond ``max_m`` read ±inf (a faster query)."""
        lat = self.lattice
        p = np.asarray(p_xyz, float).reshape(-1, 3)
        if self._crossings is None:
            self._crossings = cKDTree(zero_crossings_m(lat))
        if self._crossings.n == 0:
            d = np.full(len(p), np.inf)
        else:
            d, _ = self._crossings.query(p[:, : lat.dim], distance_upper_bound=max_m)
        mu = RegularGridInterpolator(lat.axes, lat.mean_m, bounds_error=False, fill_value=np.inf)(p[:, : lat.dim])
        d = np.where(mu < 0, -d, d)
        if lat.dim == 3:
            d = np.where(p[:, 2] >= self.min_z_m - 1e-12, d, -np.inf)
        return d

    def segments_free(self, a_xyz: np.ndarray, b_xyz: np.ndarray, step_m: float | None = None,
                      clearance_m: float | np.ndarray | None = None, euclidean: bool = False) -> np.ndarray:
        """For each segment a→b ((S, 3) each), whether all its samples (evenly spaced, at most ``step_m``
        apart, default a quarter of the smallest lattice spacing; both ends included) keep c ≥
        ``clearance_m`` (a scalar or one per segment; default the margin); ``euclidean``: c is
        :meth:`surface_distance_at`, not the graph's clearance field."""
        a = np.asarray(a_xyz, float).reshape(-1, 3)
        b = np.asarray(b_xyz, float).reshape(-1, 3)
        if not len(a):
            return np.zeros(0, bool)
        step = step_m if step_m is not None else float(np.min(self.lattice.spacing_m)) / 4.0
        # each segment its own count: one long segment no longer samples every short one as finely
        count = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(np.int64) + 1, 2)
        first = np.cumsum(count) - count
        seg = np.repeat(np.arange(len(a)), count)
        t = (np.arange(int(count.sum())) - first[seg]) / (count[seg] - 1)
        pts = a[seg] + t[:, None] * (b - a)[seg]
        need = np.broadcast_to(np.asarray(self.margin_m if clearance_m is None else clearance_m, float), (len(a),))
        if euclidean:  # distances beyond the largest need do not matter (a bounded query is faster)
            mu = self.surface_distance_at(pts, max_m=float(np.max(need, initial=0.0)) + 1e-3)
        else:
            mu = self.clearance_m(pts)
        return np.logical_and.reduceat(mu >= need[seg] - 1e-9, first)

    def node_clearance_m(self, node: np.ndarray) -> np.ndarray:
        """The clearance each node keeps: the margin, or the finger's room at a narrow node."""
        node = np.asarray(node, dtype=np.int64)
        if self.finger_m is None:
            return np.full(node.shape, self.margin_m)
        c = self.clearance_lattice_m.ravel()[self.grid_of_node[node]]
        return np.where(c >= self.margin_m, self.margin_m, self.finger_m)


CLEARANCES = ("distance", "mean")
_THREADED_QUERY_MIN = 32768  # lattice nodes from which the surface-distance query runs on every core


def edge_zero_crossings(values: np.ndarray, axes) -> np.ndarray:
    """(K, dim) points where a lattice field changes sign along an axis edge (linear interpolation
    between the two nodes), world frame."""
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


def zero_crossings_m(lattice: MapLattice) -> np.ndarray:
    """(K, dim) samples of the estimate's zero level set: the edge crossings of the lattice mean μ."""
    return edge_zero_crossings(lattice.mean_m, lattice.axes)


def surface_distance_m(lattice: MapLattice, max_m: float = np.inf, crossings: cKDTree | None = None) -> np.ndarray:
    """Signed distance (lattice shape, m; < 0 inside) from each lattice node to the zero level
    set of the lattice mean: the nearest zero crossing of μ on an axis edge (linear
    interpolation), sign of μ. Nodes farther than ``max_m`` (or all, when μ has no zero
    crossing) get ±``max_m``: finite, so that the field interpolates. ``crossings``: the k-d tree
    of :func:`zero_crossings_m` when the caller holds it (None: built here)."""
    mu = lattice.mean_m
    tree = crossings if crossings is not None else cKDTree(zero_crossings_m(lattice))
    sign = np.where(mu < 0, -1.0, 1.0)
    if tree.n == 0:
        return sign * max_m
    grid = lattice.grid_xyz()[:, : lattice.dim]
    # Threads (each node's answer is the same on any number of cores) pay on the 3D lattice (48³:
    # 83 -> 47 ms on 2 cores), not on a 2D one (128²: the same within noise).
    d, _ = tree.query(grid, distance_upper_bound=max_m, workers=-1 if len(grid) >= _THREADED_QUERY_MIN else 1)
    return sign * np.minimum(d, max_m).reshape(mu.shape)


def shaft_column_min(field: np.ndarray, z_axis_m: np.ndarray, length_m: float) -> np.ndarray:
    """s[..., k] = min of ``field`` over the nodes k + 1 … k + K of the same (x, y) column, K the nodes
    within ``length_m`` above (z the last axis; +inf where none: above the lattice nothing limits)."""
    dz = float(z_axis_m[1] - z_axis_m[0])
    K = min(int(np.floor(length_m / dz + 1e-9)), field.shape[-1] - 1)
    win = np.full(field.shape, np.inf)  # win[k] = min over the next p nodes, p doubling up to K
    if K < 1:
        return win
    win[..., :-1] = field[..., 1:]
    p = 1
    while 2 * p <= K:
        nxt = win.copy()
        np.minimum(nxt[..., :-p], win[..., p:], out=nxt[..., :-p])
        win, p = nxt, 2 * p
    out = win.copy()  # the next K = the next p and the p ending K nodes up (they overlap)
    if K > p:
        np.minimum(out[..., :-(K - p)], win[..., K - p:], out=out[..., :-(K - p)])
    return out


def _view(padded: np.ndarray, off: tuple, shape: tuple) -> np.ndarray:
    """``padded`` (padded by 1) shifted by ``off``: value at lattice index a + off."""
    return padded[tuple(slice(1 + o, 1 + o + n) for o, n in zip(off, shape))]


def _lattice_edges(free: np.ndarray, spacing_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges (8 / 26 neighbours, each once) between ``free`` lattice nodes whose every lattice node of the
    box the edge spans is free: flat lattice indices (src, dst) and lengths (m)."""
    shape, d = free.shape, free.ndim
    padded = np.pad(free, 1, constant_values=False)
    strides = np.array([int(np.prod(shape[k + 1:])) for k in range(d)])
    rows, cols, lens = [], [], []
    for off in itertools.product((-1, 0, 1), repeat=d):
        if off <= (0,) * d:  # each undirected edge once: lexicographically positive offsets
            continue
        box = free.copy()
        for sub in itertools.product(*[(0, o) if o else (0,) for o in off]):
            if any(sub):
                box &= _view(padded, sub, shape)
        src = np.flatnonzero(box.ravel())
        rows.append(src)
        cols.append(src + int(np.dot(off, strides)))
        lens.append(np.full(len(src), float(np.linalg.norm(np.array(off) * spacing_m))))
    if not rows:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(lens)


def _symmetric(src: np.ndarray, dst: np.ndarray, length_m: np.ndarray, n: int) -> sp.csr_matrix:
    return sp.coo_matrix((np.concatenate([length_m, length_m]), (np.concatenate([src, dst]), np.concatenate([dst, src]))),
                         shape=(n, n)).tocsr()


def _bridge(free: np.ndarray, edges: tuple, narrow: np.ndarray, max_m: float,
            spacing_m: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Join each free-space component to the largest by the shortest lattice path (at most ``max_m``)
    through ``narrow`` nodes (free at the finger's own clearance), if there is one: the nodes and
    edges of those paths added to ``free`` and ``edges`` (flat lattice indices)."""
    n = free.size
    src, dst, ln = edges
    _, comp = csg.connected_components(_symmetric(src, dst, ln, n), directed=False)
    ids = np.flatnonzero(free.ravel())
    if len(ids) == 0 or len(np.unique(comp[ids])) < 2:
        return free, edges
    main = np.bincount(comp[ids]).argmax()
    targets = ids[comp[ids] == main]
    fs, fd, fl = _lattice_edges(narrow | free, spacing_m)
    fine = _symmetric(fs, fd, fl, n)
    free = free.copy()
    add_s: list[np.ndarray] = [np.zeros(0, np.int64)]
    add_d: list[np.ndarray] = [np.zeros(0, np.int64)]
    for c in np.unique(comp[ids]):
        if c == main:
            continue
        dist, pred, _ = csg.dijkstra(fine, indices=ids[comp[ids] == c], min_only=True, return_predecessors=True,
                                     limit=max_m)
        t = targets[np.isfinite(dist[targets])]
        if not len(t):
            continue
        path = [int(t[np.argmin(dist[t])])]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        path = np.array(path)
        free.ravel()[path] = True
        add_s.append(path[:-1])
        add_d.append(path[1:])
    new_s, new_d = np.concatenate(add_s), np.concatenate(add_d)
    # each edge once: a path may run along edges the graph has (another cut-off component's) or another path's
    key = np.minimum(new_s, new_d) * n + np.maximum(new_s, new_d)
    _, first = np.unique(key, return_index=True)
    keep = np.zeros(len(key), bool)
    keep[first] = True
    keep &= ~np.isin(key, np.minimum(src, dst) * n + np.maximum(src, dst))
    new_s, new_d = new_s[keep], new_d[keep]
    step = np.stack(np.unravel_index(new_s, free.shape), axis=1) - np.stack(np.unravel_index(new_d, free.shape), axis=1)
    lens = np.concatenate([ln, np.linalg.norm(step * spacing_m, axis=1)])
    return free, (np.concatenate([src, new_s]), np.concatenate([dst, new_d]), lens)


def _narrow(allowed: np.ndarray, cl: np.ndarray, margin_m: float, finger_m: float, penalty: float,
            spacing_m: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Nodes where the finger fits (c ≥ ``finger_m``) and their lattice edges; an edge with an end
    inside the margin (c < ``margin_m``) is ``penalty`` times its length (flat lattice indices)."""
    free = allowed & (cl >= finger_m)
    src, dst, ln = _lattice_edges(free, spacing_m)
    flat = cl.ravel()
    tight = (flat[src] < margin_m) | (flat[dst] < margin_m)
    return free, (src, dst, np.where(tight, penalty * ln, ln))


def build_free_graph(
    lattice: MapLattice,
    margin_m: float,
    shell_m: float = 0.0,
    min_z_m: float = -np.inf,
    p_inside_max: float | None = None,
    clearance: str = "mean",
    bridge_clearance_m: float = 0.0,
    bridge_max_m: float = 0.0,
    narrow_penalty: float = 0.0,
    shaft_length_m: float = 0.0,
    shaft_clearance_m: float = 0.0,
) -> FreeSpaceGraph:
    """Free-space graph of a lattice (see the module docstring for the rules).

    Args:
        lattice: estimator lattice with the GP mean/variance.
        margin_m: minimum μ (≈ distance of the tip centre from the estimated surface).
        shell_m: keep only nodes with μ ≤ margin + shell (0 = all free space).
        min_z_m: 3D only: lowest allowed node height (table + margin + tip radius).
        p_inside_max: if set, also drop nodes with Φ(−μ/σ) above it.
        clearance: 'distance' (to the estimated surface) or 'mean' (μ); see the module docstring.
        bridge_clearance_m, bridge_max_m: with ``bridge_max_m > 0``, a component of free space cut off
            from the largest (the estimate narrows a concavity's mouth below twice the margin) is joined
            to it by the shortest lattice path, at most ``bridge_max_m`` long, through nodes with
            clearance ≥ ``bridge_clearance_m`` (the finger's own room); those nodes join the graph.
        narrow_penalty: > 0 (with ``bridge_clearance_m < margin_m``): every node with the finger's room,
            c ≥ ``bridge_clearance_m``, is free, and an edge with an end inside the margin counts
            ``narrow_penalty`` × its length: paths may pass where the estimate leaves the finger room but not
            the margin (a slot it narrows), at a price. Shortcuts keep the margin; a candidate's last
            segment from a narrow node keeps the finger's room (``finger_m``); the bridge is not needed
            (nothing with the finger's room is cut off).
        shaft_length_m, shaft_clearance_m: 3D, ``shaft_length_m > 0``: a node is free only when the column
            above it up to ``shaft_length_m`` keeps clearance ``shaft_clearance_m`` too (module docstring).
    """
    mu = lattice.mean_m
    crossings = None
    if clearance == "distance":
        # beyond margin + shell a node's exact distance does not matter (free, or outside the band)
        reach = margin_m + shell_m if shell_m > 0 else margin_m
        crossings = cKDTree(zero_crossings_m(lattice))  # the graph's surface_distance_at reads it too
        cl = surface_distance_m(lattice, max_m=reach + 2.0 * float(np.max(lattice.spacing_m)), crossings=crossings)
    elif clearance == "mean":
        cl = mu
    else:
        raise ValueError(f"clearance must be one of {CLEARANCES}, got '{clearance}'")
    allowed = np.ones(lattice.shape, bool)
    if p_inside_max is not None:
        sigma = np.sqrt(np.maximum(lattice.variance_m2, 1e-300))
        allowed &= ndtr(-mu / sigma) <= p_inside_max
    if lattice.dim == 3:
        allowed &= (lattice.axes[2] >= min_z_m)[None, None, :]
    if shell_m > 0:
        allowed &= cl <= margin_m + shell_m
    rod_field = None
    if lattice.dim == 3 and shaft_length_m > 0:  # the rod above the tip: free only under a clear column
        rod_field = cl
        cl = np.minimum(cl, shaft_column_min(cl, lattice.axes[2], shaft_length_m) - shaft_clearance_m + margin_m)
    finger_m = None
    if narrow_penalty > 0 and bridge_clearance_m < margin_m:  # no bridge: nothing with the finger's room is cut off
        free, edges = _narrow(allowed, cl, margin_m, bridge_clearance_m, narrow_penalty, lattice.spacing_m)
        finger_m = float(bridge_clearance_m)
    else:
        free = allowed & (cl >= margin_m)
        edges = _lattice_edges(free, lattice.spacing_m)
        if bridge_max_m > 0 and bridge_clearance_m < margin_m:
            free, edges = _bridge(free, edges, allowed & (cl >= bridge_clearance_m), bridge_max_m,
                                  lattice.spacing_m)
    node_of_grid = np.full(free.size, -1, dtype=np.int64)
    grid_of_node = np.flatnonzero(free.ravel())
    node_of_grid[grid_of_node] = np.arange(len(grid_of_node))
    xyz = lattice.grid_xyz()[grid_of_node]
    src, dst, ln = edges
    length = _symmetric(node_of_grid[src], node_of_grid[dst], ln, len(grid_of_node))
    graph = FreeSpaceGraph(
        lattice=lattice, free=free, node_of_grid=node_of_grid, grid_of_node=grid_of_node,
        xyz=xyz, length_m=length, margin_m=float(margin_m),
        min_z_m=float(min_z_m) if lattice.dim == 3 else -np.inf,
        clearance_field_m=None if clearance == "mean" and rod_field is None else cl, finger_m=finger_m,
        shaft_field_m=rod_field, shaft_length_m=float(shaft_length_m) if rod_field is not None else 0.0,
    )
    graph._crossings = crossings
    return graph
