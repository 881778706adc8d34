"""Scalable GPIS: local GP experts on an octree (quadtree in 2D) over a global anchor GP,
blended by a partition of unity and evaluated on a narrow band of the lattice.

Model (world frame, metres). The anchor GP is the exact GP on a thinned subset A of the
observations (a contact joins A when it is farther than ``anchor_spacing_m`` from every
anchor, up to ``max_anchors``); its mean mu_A carries the far field and the inside/outside
sign where no local data are. Each leaf e of the tree is an expert: the exact GP (same
kernel, zero prior mean) on every observation row inside its *data box* (its cell grown by
``context`` times the cell size on each side), fitted to the residuals r = y - mu_A(X)
(values and gradient components). With C^1 partition-of-unity weights w_e (1 inside the
cell shrunk by ``blend`` cell sizes, 0 outside the cell grown by it)

    mu(x)     = mu_A(x) + sum_e w_e(x) k_e(x)^T alpha_e / sum_e w_e(x),
    sigma2(x) = min(sigma2_A(x), sum_e w_e(x) sigma2_e(x) / sum_e w_e(x)),

both variances being exact posteriors on subsets of the data, hence upper bounds of the
exact one. A GP posterior at a point surrounded by data depends almost only on the data
nearby (screening), so near the contacts this matches the exact GP on all data; tests and
``scripts/bench.sh gpis`` measure the error against it.

Cost per contact: one Cholesky append (O(m^2) for m rows) in each expert whose data box
holds the point (about (1 + 2 context)^(d-1) experts for points on a surface), and the
band lattice nodes of those experts. A leaf holding more than ``leaf_capacity`` contacts
splits into 2^d children (refactored once), so every expert stays small and the state is
O(n m) for n observations. An anchor joins the anchor GP as it comes (a probe's free-space end
always does, however near other anchors: it can remove estimated solid anywhere); the commit
recomputes mu_A at every row and band node (O((n + band) |A|)) and every expert's residuals
(O(m^2) each). Anchors waiting for a batch left the far field without the newest surface: after
a slide up a new side the local mean differed in sign from the exact one at hundreds of nodes.

The lattice mean is exact-blended on the *band*: nodes with |mu_A| < ``band_m`` or within
``band_m`` of an observation (the band only grows); elsewhere it is mu_A interpolated
(multilinear) from a coarse lattice (every ``coarse_stride``-th node), which only has to
get the sign right there. The lattice variance is the formula above on the band (each expert
keeps |W[:, node]|^2 of its band nodes up to date with W, so sigma2_e = k0 - |W[:, node]|^2 costs
no solve) and sigma2_A interpolated the same way elsewhere (an upper bound); variances at given
points (the candidates) use the formula above.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp
from scipy.linalg import solve_triangular

from .expert import ExpertGP
from .gp import GPIS, VALUE, FactorError, MeanFn, cross_cov, gradient_rows, zero_mean
from .kernels import Kernel

_CHUNK_ELEMS = 2_000_000  # elements of the (queries, anchor points, d) difference array per chunk


def _smoothstep(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """C^1 ramp S(s) = 3s^2 - 2s^3 on [0, 1] (clipped) and its derivative."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s), 6.0 * s * (1.0 - s)


def _interpolation_matrix(axes: list[np.ndarray], P: np.ndarray) -> sp.csr_matrix:
    """Sparse (N, prod(len(axes))) multilinear interpolation from the lattice ``axes`` to P."""
    N, d = P.shape
    shape = [len(a) for a in axes]
    lo_idx, frac = [], []
    for i, a in enumerate(axes):
        j = np.clip(np.searchsorted(a, P[:, i], side="right") - 1, 0, len(a) - 2)
        lo_idx.append(j)
        frac.append(np.clip((P[:, i] - a[j]) / (a[j + 1] - a[j]), 0.0, 1.0))
    rows, cols, vals = [], [], []
    for code in range(2 ** d):
        bits = [(code >> k) & 1 for k in range(d)]
        idx = [lo_idx[i] + bits[i] for i in range(d)]
        w = np.prod([frac[i] if bits[i] else 1.0 - frac[i] for i in range(d)], axis=0)
        rows.append(np.arange(N))
        cols.append(np.ravel_multi_index(idx, shape))
        vals.append(w)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(N, int(np.prod(shape))))


class _CandCache:
    """One expert's columns for the query points of the last :meth:`LocalGPIS.predict_candidates`.

    Columns in the order of ``ids`` (the caller's ids of the points, equal ids = equal
    coordinates): Wv = L^-1 K(rows, points) (n, q) and, where ``g_ok``, Wg = L^-1 K(rows,
    gradient rows of the points) (n, q d); an append only adds their new rows. r, dr, v:
    the expert's residual mean, its gradient and its variance at the points, valid for the
    factor ``uid`` with ``n`` rows at beta revision ``rev``; w, dw: the raw weight and its
    gradient there.
    """

    def __init__(self, uid: int, n: int, rev: int, ids: np.ndarray, P: np.ndarray, w: np.ndarray, dw: np.ndarray,
                 Wv: np.ndarray, Wg: np.ndarray, g_ok: np.ndarray, r: np.ndarray, dr: np.ndarray,
                 v: np.ndarray) -> None:
        self.uid, self.n, self.rev = uid, n, rev
        self.ids, self.P, self.w, self.dw = ids, P, w, dw
        self.Wv, self.Wg, self.g_ok = Wv, Wg, g_ok
        self.r, self.dr, self.v = r, dr, v
        self._blend: Optional[np.ndarray] = None

    @property
    def blend(self) -> np.ndarray:
        """(q, 3 + 2d) per point: w r, w, w v, dw r + w dr, dw (what the blend sums)."""
        if self._blend is None:
            w = self.w[:, None]
            self._blend = np.hstack([w * self.r[:, None], w, w * self.v[:, None],
                                     self.dw * self.r[:, None] + w * self.dr, self.dw])
        return self._blend

    def take(self, cols: np.ndarray) -> "_CandCache":
        d = self.P.shape[1]
        gcols = (cols[:, None] * d + np.arange(d)).ravel()
        return _CandCache(self.uid, self.n, self.rev, self.ids[cols], self.P[cols], self.w[cols], self.dw[cols],
                          self.Wv[:, cols], self.Wg[:, gcols], self.g_ok[cols], self.r[cols], self.dr[cols],
                          self.v[cols])

    def nbytes(self) -> int:
        return int(self.Wv.nbytes + self.Wg.nbytes + self.P.nbytes * 4)


class _Leaf:
    """One expert: a tree cell, its data box, and (once active) the exact GP on its rows."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, depth: int, kernel: Kernel, dim: int,
                 context_m: float, blend: float, jitter: float) -> None:
        self.lo, self.hi, self.depth = lo, hi, depth
        size = hi - lo
        self.dlo, self.dhi = lo - context_m, hi + context_m  # data box
        self.context_m = context_m
        self.centre, self.half = 0.5 * (lo + hi), 0.5 * size
        self.ramp = np.full(dim, blend * min(float(size.min()), context_m))  # < the context
        self.blo, self.bhi = lo - self.ramp, hi + self.ramp  # weight support
        self.own: list[int] = []  # observations inside the cell
        self.rows = np.zeros(0, dtype=np.int64)  # global row ids inside the data box, in factor order
        self.gp = ExpertGP(kernel, dim, jitter)
        self.active = False  # factor built and maintained (only where the band or a query needs it)
        # band nodes in the weight support: lattice ids, raw weights, contribution k(node)^T alpha,
        # and W = L^-1 K(rows, nodes) (gp.n, len(nodes)) in a buffer with spare rows (appends
        # write rows, no copy): contribution = W^T beta, so an append needs no alpha
        self.nodes = np.zeros(0, dtype=np.int64)
        self.w = np.zeros(0)
        self._wbuf = np.zeros((0, 0))
        self.contrib = np.zeros(0)
        self.colsq = np.zeros(0)  # per band node: |W[:, node]|^2 (the expert's variance there is k0 - colsq)
        self.cand: Optional[_CandCache] = None  # the last candidates' columns (predict_candidates)

    @property
    def W(self) -> np.ndarray:
        """L^-1 K(rows, nodes) (gp.n, len(nodes)) (a view)."""
        return self._wbuf[: self.gp.n]

    def set_W(self, W: np.ndarray) -> None:
        self._wbuf = np.zeros((len(W) + max(16, len(W) // 4), W.shape[1]))
        self._wbuf[: len(W)] = W

    def append_W_rows(self, R: np.ndarray, n_old: int) -> None:
        """Rows n_old.. of W (after the factor grew by len(R) rows)."""
        need = n_old + len(R)
        if need > len(self._wbuf):
            buf = np.zeros((need + max(16, need // 4), self._wbuf.shape[1]))
            buf[:n_old] = self._wbuf[:n_old]
            self._wbuf = buf
        self._wbuf[n_old:need] = R

    def append_W_cols(self, C: np.ndarray) -> None:
        """Columns for new nodes (gp.n, k).

        An expert a query activated before any band node reached it has W without columns, and its
        appends add no rows to it (nothing to hold): the buffer may then be shorter than the factor,
        and only the columns it has are copied.
        """
        n, k = self.gp.n, self._wbuf.shape[1]
        buf = np.zeros((len(self._wbuf) if len(self._wbuf) >= n else n + 16, k + C.shape[1]))
        if k:
            buf[:n, :k] = self._wbuf[:n]
        buf[:n, k:] = C
        self._wbuf = buf

    def weight(self, X: np.ndarray, grad: bool = False):
        """Raw partition-of-unity weight w(x) (N,) (and its gradient (N, d))."""
        t = (self.half + self.ramp - np.abs(X - self.centre)) / (2.0 * self.ramp)
        s, ds = _smoothstep(t)
        w = np.prod(s, axis=1)
        if not grad:
            return w
        dsdx = -ds * np.sign(X - self.centre) / (2.0 * self.ramp)
        g = np.empty_like(X)
        for i in range(X.shape[1]):
            g[:, i] = dsdx[:, i] * np.prod(np.delete(s, i, axis=1), axis=1)
        return w, g


class LocalGPIS:
    """Local-expert GPIS with an anchor GP (see the module docstring for the math).

    Args:
        kernel, dim, mean_fn, jitter: as for :class:`GPIS` (the anchor GP uses ``mean_fn``).
        bounds_m: (2, dim) box holding every observation (the tree's root cell).
        lattice_axes: per axis the lattice node coordinates (the map).
        leaf_capacity: observations in a leaf before it splits.
        max_rows: a leaf wider than its context whose data box holds more rows than this
            splits too (0 = no limit).
        context_m, context_spacings: data box margin: an expert sees the data
            c = max(context_m, context_spacings * s) beyond its cell, s the spacing of
            the observations where its parent split (parent size / own^(1/(d-1)),
            surface data), at most 2.5 context_m: sparse data need a wider context than
            dense data (measured).
        blend: weight ramp half-width, as a fraction of min(cell size, context_m) (< 1).
        min_leaf_m: leaves never split below this size.
        anchor_spacing_m, max_anchors: the anchor subset.
        band_m: lattice band half-width around the zero level set and the observations.
        coarse_stride: the anchor GP's lattice takes every n-th node per axis.
    """

    def __init__(self, kernel: Kernel, dim: int, mean_fn: Optional[MeanFn], jitter: float,
                 bounds_m: np.ndarray, lattice_axes: list[np.ndarray], *, leaf_capacity: int = 32,
                 context_m: float = 0.012, context_spacings: float = 1.6, blend: float = 0.25, min_leaf_m: float = 0.004,
                 anchor_spacing_m: float = 0.015, max_anchors: int = 256, band_m: float = 0.008, coarse_stride: int = 3,
                 max_rows: int = 0) -> None:
        if not 0 < blend < 1:
            raise ValueError(f"local blend {blend} must be in (0, 1)")
        if not context_m > 0:
            raise ValueError(f"local context_m {context_m} must be > 0")
        if leaf_capacity < 1 or max_anchors < 1 or coarse_stride < 1:
            raise ValueError("leaf_capacity, max_anchors and coarse_stride must be >= 1")
        self.kernel, self.dim, self.jitter = kernel, dim, float(jitter)
        self._k0 = kernel.k0
        self.mean_fn = mean_fn or zero_mean
        self.bounds_m = np.asarray(bounds_m, float)
        self.axes = [np.asarray(a, float) for a in lattice_axes]
        self.shape = tuple(len(a) for a in self.axes)
        self.leaf_capacity, self.context_m, self.blend = int(leaf_capacity), float(context_m), float(blend)
        if not context_spacings >= 0:
            raise ValueError(f"local context_spacings {context_spacings} must be >= 0")
        self.context_spacings = float(context_spacings)
        self.min_leaf_m = float(min_leaf_m)
        self.max_rows = int(max_rows) if max_rows > 0 else 1 << 62
        self.anchor_spacing_m, self.max_anchors = float(anchor_spacing_m), int(max_anchors)
        self.band_m = float(band_m)
        grids = np.meshgrid(*self.axes, indexing="ij")
        self._lattice = np.stack([g.ravel() for g in grids], axis=-1)
        self._coarse_axes = [np.unique(np.r_[a[::coarse_stride], a[-1]]) for a in self.axes]
        cg = np.meshgrid(*self._coarse_axes, indexing="ij")
        self._coarse = np.stack([g.ravel() for g in cg], axis=-1)
        self._interp = _interpolation_matrix(self._coarse_axes, self._lattice)
        self.reset()

    # -- state ---------------------------------------------------------------
    def reset(self) -> None:
        """Drop every observation."""
        d = self.dim
        self.n_obs = 0
        self.n_rows = 0
        self._X = np.zeros((0, d))
        self._t = np.zeros(0, dtype=np.int64)
        self._y = np.zeros(0)
        self._noise = np.zeros(0)
        self._resid = np.zeros(0)  # y - mu_A per row
        self._obs_pts = np.zeros((0, d))
        self._obs_start: list[int] = []
        self._obs_len: list[int] = []
        self.anchor = GPIS(self.kernel, d, self.mean_fn, self.jitter)
        self.anchor.set_eval_points(self._coarse)
        self._anchor_alpha = np.zeros(0)
        self._anchor_pts: Optional[tuple] = None  # _anchor_weights(): (rev, points, a_v, a_g)
        self._anchor_rev = 0  # bumped at every anchor commit (the anchor mean/variance changed)
        self._qids: dict[bytes, int] = {}  # predict_candidates: coordinates -> id (the last call's points)
        self._next_qid = 0
        self._anchor_q: Optional[tuple] = None  # predict_candidates: (rev, ids, mean_a, grad_a, var_a)
        self._anchor_obs: list[int] = []
        self.leaves = [self._new_leaf(self.bounds_m[0].copy(), self.bounds_m[1].copy(), 0)]
        self._boxes: Optional[dict] = None
        M = len(self._lattice)
        self._band = np.zeros(M, dtype=bool)
        self._num = np.zeros(M)  # sum_e w_e r_e on band nodes
        self._wsum = np.zeros(M)  # sum_e w_e on band nodes
        self._mu_a_band = np.zeros(M)  # exact mu_A on band nodes
        self._vnum = np.zeros(M)  # sum_e w_e sigma2_e on band nodes
        self._refresh_coarse()
        self._add_band_nodes(np.flatnonzero(np.abs(self._mu_a_lat) < self.band_m))

    def _new_leaf(self, lo: np.ndarray, hi: np.ndarray, depth: int, spacing_m: float = np.inf) -> _Leaf:
        c = min(max(self.context_m, self.context_spacings * spacing_m), 2.5 * self.context_m)
        return _Leaf(lo, hi, depth, self.kernel, self.dim, c, self.blend, self.jitter)

    @property
    def n(self) -> int:
        """Observation rows held (as GPIS.n)."""
        return self.n_rows

    @property
    def n_anchors(self) -> int:
        return len(self._anchor_obs)

    @property
    def n_active(self) -> int:
        """Experts with a factor."""
        return sum(lf.active for lf in self.leaves)

    def state_bytes(self) -> int:
        """Bytes held by the factors, caches (band and candidate columns), row arrays and
        lattice arrays (the state's size)."""
        b = sum(lf.gp.nbytes() + lf._wbuf.nbytes + lf.rows.nbytes + 4 * lf.nodes.nbytes
                + (lf.cand.nbytes() if lf.cand is not None else 0) for lf in self.leaves)
        b += self.anchor._L.nbytes + sum(v.nbytes for v in (self.anchor._V or []))
        b += self._X.nbytes + 5 * self._y.nbytes
        b += sum(a.nbytes for a in (self._band, self._num, self._wsum, self._mu_a_band, self._mu_a_lat,
                                     self._var_a_lat, self._vnum))
        return int(b)

    def _box_arrays(self) -> dict:
        """(L, d) arrays of the leaves' cells, data boxes and weight supports (cached)."""
        if self._boxes is None:
            self._boxes = {k: np.array([getattr(lf, k) for lf in self.leaves])
                           for k in ("lo", "hi", "dlo", "dhi", "blo", "bhi")}
        return self._boxes

    def _leaves_overlapping(self, lo: np.ndarray, hi: np.ndarray, which: str) -> np.ndarray:
        """Indices of the leaves whose box ``which`` ('d' data, 'b' weight) meets [lo, hi]."""
        b = self._box_arrays()
        return np.flatnonzero(np.all((b[which + "hi"] >= lo) & (b[which + "lo"] <= hi), axis=1))

    # -- anchor GP -------------------------------------------------------------
    def _anchor_weights(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The anchor GP's alpha = K^-1 (y - m) gathered per point: points P (p, d), the weight of
        their value rows a_v (p,) and of their gradient rows a_g (p, d) (zero where a point has
        none); kept until the next commit."""
        if self._anchor_pts is None or self._anchor_pts[0] != self._anchor_rev:
            t, a = np.asarray(self.anchor.t), self._anchor_alpha
            P, inv = np.unique(self.anchor.X, axis=0, return_inverse=True)
            inv = inv.ravel()
            a_v = np.bincount(inv, weights=np.where(t < 0, a, 0.0), minlength=len(P))
            a_g = np.stack([np.bincount(inv, weights=np.where(t == i, a, 0.0), minlength=len(P))
                            for i in range(self.dim)], axis=1)
            self._anchor_pts = (self._anchor_rev, P, a_v, a_g)
        return self._anchor_pts[1:]

    def _mu_a(self, X: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Anchor posterior mean of the rows (X, t): values or gradient components.

        mu_A(q) = m(q) + sum_p [k(r) a_v(p) - g(r) u.a_g(p)] with u = q - p, r = |u| (the value
        and gradient blocks of :func:`cross_cov`), and its derivative
        d_i mu_A(q) = d_i m(q) + sum_p [u_i (g a_v - h u.a_g) - g a_g,i]: one pass over the anchor
        points, not over their rows."""
        mv, mg = self.mean_fn(X)
        out = np.where(t < 0, mv, mg[np.arange(len(t)), np.maximum(t, 0)])
        if not self.anchor.n:
            return out
        P, a_v, a_g = self._anchor_weights()
        step = max(1, _CHUNK_ELEMS // (len(P) * self.dim))
        for s in range(0, len(t), step):
            e = min(len(t), s + step)
            U = X[s:e, None, :] - P[None, :, :]  # (c, p, d)
            k, g, h = self.kernel.radial(np.sqrt(np.einsum("cpd,cpd->cp", U, U)))
            ua = np.einsum("cpd,pd->cp", U, a_g)
            tc = t[s:e]
            val = tc < 0
            if val.any():
                out[s:e][val] += k[val] @ a_v - np.einsum("cp,cp->c", g[val], ua[val])
            if not val.all():
                gr = np.flatnonzero(~val)
                i = tc[gr]
                W = g[gr] * a_v - h[gr] * ua[gr]
                out[s + gr] += (np.einsum("cp,cp->c", W, U[gr, :, i]) - np.einsum("cp,cp->c", g[gr], a_g[:, i].T))
        return out

    def _refresh_coarse(self) -> None:
        """Anchor mean/variance on the fine lattice, interpolated from the coarse one."""
        self._mu_a_lat = self._interp @ self.anchor.eval_mean()
        self._var_a_coarse = self.anchor.eval_variance()
        self._var_a_lat = self._interp @ self._var_a_coarse

    def _commit_anchor(self, i: int) -> None:
        """Add observation i to the anchor GP; recompute every residual and expert."""
        s, k = self._obs_start[i], self._obs_len[i]
        try:
            self.anchor.add_rows(self._X[s:s + k], self._t[s:s + k], self._y[s:s + k], self._noise[s:s + k])
        except FactorError:
            return  # an anchor the anchor GP cannot take stays a local observation only
        self._anchor_obs.append(i)
        self._anchor_rev += 1
        self._anchor_alpha = self.anchor.alpha
        self._resid = self._y - self._mu_a(self._X, self._t)
        for lf in self.leaves:
            if lf.active:
                lf.gp.set_residuals(self._resid[lf.rows])
        self._refresh_coarse()
        band = np.flatnonzero(self._band)
        self._mu_a_band[band] = self._mu_a(self._lattice[band], np.full(len(band), VALUE))
        for lf in self.leaves:
            self._update_contrib(lf)
        self._add_band_nodes(np.flatnonzero(~self._band & (np.abs(self._mu_a_lat) < self.band_m)))

    # -- experts -----------------------------------------------------------------
    def _activate(self, lf: _Leaf) -> None:
        """Build the expert's factor from its rows (O(m^3)) and start maintaining it."""
        r = lf.rows
        lf.gp.build(self._X[r], self._t[r], self._resid[r], self._noise[r])
        lf.active = True
        lf.set_W(np.zeros((lf.gp.n, 0)))  # invariant for an active leaf: W is (gp.n, len(nodes))
        if len(lf.nodes):
            K = cross_cov(self.kernel, lf.gp.X, lf.gp.t, self._lattice[lf.nodes], np.full(len(lf.nodes), VALUE))
            lf.set_W(lf.gp.solve(K) if lf.gp.n else K)
            self._update_contrib(lf)
            self._update_variance(lf, np.sum(lf.W * lf.W, axis=0))

    def _update_contrib(self, lf: _Leaf) -> None:
        if not len(lf.nodes):
            return
        c = lf.W.T @ lf.gp.beta if lf.gp.n else np.zeros(len(lf.nodes))
        self._num[lf.nodes] += lf.w * (c - lf.contrib)
        lf.contrib = c

    def _update_variance(self, lf: _Leaf, colsq: np.ndarray) -> None:
        """New |W|^2 columns of an expert's band nodes: its variance k0 - colsq there in the blend."""
        self._vnum[lf.nodes] += lf.w * (lf.colsq - colsq)
        lf.colsq = colsq

    # -- band ------------------------------------------------------------------
    def _add_band_nodes(self, idx: np.ndarray) -> None:
        idx = np.unique(idx[~self._band[idx]])
        if not len(idx):
            return
        self._band[idx] = True
        P = self._lattice[idx]
        self._mu_a_band[idx] = self._mu_a(P, np.full(len(idx), VALUE))
        for j in self._leaves_overlapping(P.min(0), P.max(0), "b"):
            lf = self.leaves[j]
            inside = np.all((P >= lf.blo) & (P <= lf.bhi), axis=1)
            if inside.any():
                self._leaf_add_nodes(lf, idx[inside])

    def _leaf_add_nodes(self, lf: _Leaf, idx: np.ndarray) -> None:
        P = self._lattice[idx]
        w = lf.weight(P)
        keep = w > 0
        idx, P, w = idx[keep], P[keep], w[keep]
        if not len(idx):
            return
        if not lf.active:
            self._activate(lf)
        if lf.gp.n:
            Wn = lf.gp.solve(cross_cov(self.kernel, lf.gp.X, lf.gp.t, P, np.full(len(P), VALUE)))
            c = Wn.T @ lf.gp.beta
        else:
            Wn, c = np.zeros((0, len(idx))), np.zeros(len(idx))
        cs = np.sum(Wn * Wn, axis=0)
        lf.append_W_cols(Wn)
        lf.nodes = np.concatenate([lf.nodes, idx])
        lf.w = np.concatenate([lf.w, w])
        lf.contrib = np.concatenate([lf.contrib, c])
        lf.colsq = np.concatenate([lf.colsq, cs])
        self._wsum[idx] += w
        self._num[idx] += w * c
        self._vnum[idx] += w * (self._k0 - cs)

    def _near_nodes(self, x: np.ndarray) -> np.ndarray:
        """Lattice ids within band_m (box) of x."""
        rng = []
        for i, a in enumerate(self.axes):
            lo = np.searchsorted(a, x[i] - self.band_m)
            hi = np.searchsorted(a, x[i] + self.band_m, side="right")
            rng.append(np.arange(lo, hi))
        if any(len(r) == 0 for r in rng):
            return np.zeros(0, dtype=np.int64)
        mesh = np.meshgrid(*rng, indexing="ij")
        return np.ravel_multi_index([m.ravel() for m in mesh], self.shape)

    # -- observations ------------------------------------------------------------
    def add_observation(self, x: np.ndarray, value: float, value_noise_var: float,
                        gradient: Optional[np.ndarray] = None, gradient_noise_var: float = 0.0,
                        anchor: bool = False) -> None:
        """One point: its value and optionally its gradient (1 or 1 + d rows), as GPIS.

        ``anchor``: the point joins the anchor GP however near other anchors it is (while there are
        fewer than ``max_anchors``): for evidence about the far field, such as a free-space point,
        which can remove estimated solid anywhere, where the experts only reach their weight supports.

        Raises:
            FactorError: an expert cannot take the rows; the state is unchanged.
        """
        x = np.asarray(x, float).reshape(self.dim)
        if gradient is None:
            X, t = x[None], np.array([VALUE])
            y, nv = np.array([float(value)]), np.array([float(value_noise_var)])
        else:
            Xg, tg = gradient_rows(x[None])
            X, t = np.vstack([x, Xg]), np.r_[VALUE, tg]
            y = np.r_[float(value), np.asarray(gradient, float).reshape(self.dim)]
            nv = np.r_[float(value_noise_var), np.full(self.dim, float(gradient_noise_var))]
        if not (np.isfinite(X).all() and np.isfinite(y).all() and np.isfinite(nv).all()) or (nv < 0).any():
            raise ValueError("observation must be finite with noise variances >= 0")
        resid = y - self._mu_a(X, t)
        hit = [self.leaves[j] for j in self._leaves_overlapping(x, x, "d")]
        act = [lf for lf in hit if lf.active]
        # one cross-covariance for every active expert hit: the union of their rows
        union = np.unique(np.concatenate([lf.rows for lf in act])) if act else np.zeros(0, np.int64)
        K_union = cross_cov(self.kernel, self._X[union], self._t[union], X, t)
        K22 = cross_cov(self.kernel, X, t, X, t)
        states = [lf.gp.append(X, t, resid, nv, K_union[np.searchsorted(union, lf.rows)], K22) for lf in act]
        i, r0 = self.n_obs, self.n_rows
        self._X = np.vstack([self._X, X])
        self._t = np.concatenate([self._t, t])
        self._y = np.concatenate([self._y, y])
        self._noise = np.concatenate([self._noise, nv])
        self._resid = np.concatenate([self._resid, resid])
        self._obs_pts = np.vstack([self._obs_pts, x])
        self._obs_start.append(r0)
        self._obs_len.append(len(t))
        self.n_obs, self.n_rows = i + 1, r0 + len(t)
        rows = np.arange(r0, r0 + len(t))
        for lf in hit:
            lf.rows = np.concatenate([lf.rows, rows])
        nodes = np.unique(np.concatenate([lf.nodes for lf in act])) if act else np.zeros(0, np.int64)
        K_nodes = cross_cov(self.kernel, X, t, self._lattice[nodes], np.full(len(nodes), VALUE))  # (B, q)
        for lf, st in zip(act, states):
            n_old = lf.gp.n
            if len(lf.nodes):  # W gains B rows; the contribution W^T beta gains their share
                W2 = lf.gp.solve_rows(st, lf.W, K_nodes[:, np.searchsorted(nodes, lf.nodes)])
                lf.gp.commit(st)
                lf.append_W_rows(W2, n_old)
                dc = W2.T @ st.beta
                self._num[lf.nodes] += lf.w * dc
                lf.contrib = lf.contrib + dc
                self._update_variance(lf, lf.colsq + np.sum(W2 * W2, axis=0))
            else:
                lf.gp.commit(st)
        owner = self._owner(x)
        owner.own.append(i)
        self._add_band_nodes(self._near_nodes(x))
        size = float((owner.hi - owner.lo).min())
        # a cell wider than its context that sees many rows splits too: its children's data
        # boxes hold fewer rows (per-contact cost ~ sum of the hit experts' rows squared)
        big = len(owner.own) > self.leaf_capacity or (len(owner.rows) > self.max_rows and size > owner.context_m)
        if big and size >= 2 * self.min_leaf_m:
            self._split(owner)
        self._maybe_anchor(i, x, always=anchor)

    def _maybe_anchor(self, i: int, x: np.ndarray, always: bool = False) -> None:
        """Observation i joins the anchor GP now if it is farther than ``anchor_spacing_m`` from every
        anchor (or ``always``), while there are fewer than ``max_anchors``."""
        A = self._anchor_obs
        if len(A) >= self.max_anchors:
            return
        if always or not A or np.min(((self._obs_pts[A] - x) ** 2).sum(1)) > self.anchor_spacing_m ** 2:
            self._commit_anchor(i)

    def _owner(self, x: np.ndarray) -> _Leaf:
        """The leaf whose cell holds x (cells are half-open, closed at the root's top)."""
        b = self._box_arrays()
        top = b["hi"] >= self.bounds_m[1]
        sel = np.flatnonzero(np.all((x >= b["lo"]) & ((x < b["hi"]) | ((x == b["hi"]) & top)), axis=1))
        if len(sel):
            return self.leaves[int(sel[0])]
        gap = np.abs(np.clip(x, b["lo"], b["hi"]) - x).sum(1)
        return self.leaves[int(np.argmin(gap))]

    def _split(self, parent: _Leaf) -> None:
        """Replace a leaf by its 2^d children (each activated only if the band needs it)."""
        mid = parent.centre
        P = self._obs_pts
        boxes = []
        for code in range(2 ** self.dim):
            bits = np.array([(code >> k) & 1 for k in range(self.dim)], bool)
            boxes.append((np.where(bits, mid, parent.lo), np.where(bits, parent.hi, mid)))
        owns: list[list[int]] = [[] for _ in boxes]
        for j in parent.own:
            for k, (lo, hi) in enumerate(boxes):
                if np.all((P[j] >= lo) & ((P[j] < hi) | ((P[j] == hi) & (hi >= self.bounds_m[1])))):
                    owns[k].append(j)
                    break
            else:
                owns[0].append(j)
        # spacing of the data where the split happens: the parent's cell over its own count
        spacing = float((parent.hi - parent.lo).min()) / len(parent.own) ** (1.0 / (self.dim - 1))
        kids = [self._new_leaf(lo, hi, parent.depth + 1, spacing) for lo, hi in boxes]
        starts, lens = np.asarray(self._obs_start), np.asarray(self._obs_len)
        for kid, own in zip(kids, owns):
            kid.own = own
            inbox = np.flatnonzero(np.all((P >= kid.dlo) & (P <= kid.dhi), axis=1))
            kid.rows = (np.concatenate([np.arange(starts[j], starts[j] + lens[j]) for j in inbox])
                        if len(inbox) else np.zeros(0, np.int64))
        if len(parent.nodes):  # swap the parent's band contribution for the children's
            self._num[parent.nodes] -= parent.w * parent.contrib
            self._wsum[parent.nodes] -= parent.w
            self._vnum[parent.nodes] -= parent.w * (self._k0 - parent.colsq)
        self.leaves.remove(parent)
        self.leaves.extend(kids)
        self._boxes = None
        band = np.flatnonzero(self._band)
        Pb = self._lattice[band]
        for kid in kids:
            inside = np.all((Pb >= kid.blo) & (Pb <= kid.bhi), axis=1)
            if inside.any():
                self._leaf_add_nodes(kid, band[inside])

    # -- outputs -----------------------------------------------------------------
    def _band_mean(self) -> np.ndarray:
        out = self._mu_a_lat.copy()
        b = self._band
        out[b] = self._mu_a_band[b] + self._num[b] / np.maximum(self._wsum[b], 1e-300)
        return out

    def lattice_mean(self) -> np.ndarray:
        """(M,) mean on the lattice (C order): blended on the band, mu_A elsewhere.

        The band is first closed: a lattice edge whose ends differ in sign and of which
        only one end is in the band brings the other end in (repeated until none), so
        every zero crossing of the published mean lies between two blended nodes.
        """
        for _ in range(8):
            m = self._band_mean().reshape(self.shape)
            band = self._band.reshape(self.shape)
            add = np.zeros(self.shape, bool)
            for ax in range(self.dim):
                a = [slice(None)] * self.dim
                b = [slice(None)] * self.dim
                a[ax], b[ax] = slice(None, -1), slice(1, None)
                a, b = tuple(a), tuple(b)
                cross = (m[a] < 0) != (m[b] < 0)
                add[a] |= cross & ~band[a] & band[b]
                add[b] |= cross & band[a] & ~band[b]
            if not add.any():
                return m.ravel()
            self._add_band_nodes(np.flatnonzero(add.ravel()))
        return self._band_mean()

    def lattice_variance(self) -> np.ndarray:
        """(M,) variance on the lattice (C order): on the band min(sigma2_A, the experts' blend), as
        :meth:`predict`; elsewhere the anchor GP's (interpolated; an upper bound). Each expert's
        variance at its band nodes is k0 - |W[:, node]|^2, kept up to date with W."""
        out = np.maximum(self._var_a_lat, 0.0)
        b = self._band & (self._wsum > 0)
        blend = np.maximum(self._vnum[b] / self._wsum[b], 0.0)
        out[b] = np.minimum(out[b], blend)
        return out

    @property
    def band_mask(self) -> np.ndarray:
        return self._band.copy()

    def _anchor_var(self, P: np.ndarray) -> np.ndarray:
        """The anchor GP's variance at points P (M, d): interpolated from its coarse lattice inside the
        workspace box, predicted outside it (the prior k0 while the anchor holds no data)."""
        lo, hi = np.array([a[0] for a in self.axes]), np.array([a[-1] for a in self.axes])
        inbox = np.all((P >= lo) & (P <= hi), axis=1)
        v = np.empty(len(P))
        if inbox.any():
            v[inbox] = _interpolation_matrix(self._coarse_axes, P[inbox]) @ self._var_a_coarse
        if (~inbox).any():
            v[~inbox] = self.anchor.predict(P[~inbox])[1] if self.anchor.n else self.kernel.k0
        return v

    def predict(self, Xq: np.ndarray, return_var: bool = True, return_grad: bool = False):
        """Blended posterior mean (and variance, and mean gradient) at (N, d) points.

        Experts covering a query point are activated (built) if they were not yet. The
        anchor variance (the cap of the blended one) is interpolated from the coarse lattice
        inside the lattice box (exact outside it).
        """
        Xq = np.atleast_2d(np.asarray(Xq, float))
        N, d = Xq.shape
        mean_a = self._mu_a(Xq, np.full(N, VALUE))
        grad_a = None
        if return_grad:
            Xg, tg = gradient_rows(Xq)
            grad_a = self._mu_a(Xg, tg).reshape(N, d)
        var_a = self._anchor_var(Xq) if return_var else None
        num, wsum, vnum = np.zeros(N), np.zeros(N), np.zeros(N)
        gnum, gw = np.zeros((N, d)), np.zeros((N, d))
        for j in self._leaves_overlapping(Xq.min(0), Xq.max(0), "b"):
            lf = self.leaves[j]
            sel = np.flatnonzero(np.all((Xq >= lf.blo) & (Xq <= lf.bhi), axis=1))
            if not len(sel):
                continue
            if not lf.active:
                self._activate(lf)
            P = Xq[sel]
            w, dw = lf.weight(P, grad=True)
            if lf.gp.n:
                nq = len(P)
                if return_grad:  # value and gradient rows in one cross-covariance
                    Xg, tg = gradient_rows(P)
                    KK = cross_cov(self.kernel, lf.gp.X, lf.gp.t, np.vstack([P, Xg]), np.r_[np.full(nq, VALUE), tg])
                    K = KK[:, :nq]
                    dr = (KK[:, nq:].T @ lf.gp.alpha).reshape(nq, d)
                else:
                    K = cross_cov(self.kernel, lf.gp.X, lf.gp.t, P, np.full(nq, VALUE))
                r = K.T @ lf.gp.alpha
                if return_var:
                    V = lf.gp.solve(K)
                    v = self.kernel.k0 - np.einsum("ij,ij->j", V, V)
            else:
                r, v, dr = np.zeros(len(P)), np.full(len(P), self.kernel.k0), np.zeros((len(P), d))
            num[sel] += w * r
            wsum[sel] += w
            if return_var:
                vnum[sel] += w * v
            if return_grad:
                gnum[sel] += dw * r[:, None] + w[:, None] * dr
                gw[sel] += dw
        wsum = np.maximum(wsum, 1e-300)
        out = [mean_a + num / wsum]
        if return_var:
            out.append(np.maximum(np.minimum(var_a, vnum / wsum), 0.0))
        if return_grad:
            out.append(grad_a + gnum / wsum[:, None] - (num / wsum ** 2)[:, None] * gw)
        return out[0] if len(out) == 1 else tuple(out)

    def predict_gradient(self, Xq: np.ndarray) -> np.ndarray:
        """(N, d) gradient of the blended mean."""
        return self.predict(Xq, return_var=False, return_grad=True)[1]

    # -- candidates (cached across calls) ---------------------------------------
    def predict_candidates(self, Xq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As ``predict(Xq, return_var=True, return_grad=True)`` (mean, variance, mean
        gradient), reusing the work of the previous call for the points given again with
        the same coordinates (the map's candidates: most stay from one contact to the next).

        Per expert and point it keeps Wv = L^-1 k(rows, x) and, from the second call on
        which the expert has changed, Wg = L^-1 dk/dx: an expert that did not change since
        the last call reuses its mean, gradient and variance there; one that took rows only
        adds the new rows of W (O(B m) per point for B new rows, the band caches' rule) and
        reads mean = Wv^T beta, gradient = Wg^T beta, variance = k(0) - |Wv|^2; new points
        cost what ``predict`` costs. Exact (the first rows of a factor never change), up to
        rounding: the tests compare it with ``predict``.
        """
        Xq = np.atleast_2d(np.asarray(Xq, float))
        N, d = Xq.shape
        ids = self._query_ids(Xq)
        mean_a, grad_a, var_a = self._anchor_at(Xq, ids)
        b = self._box_arrays()
        inside = np.all((Xq[None] >= b["blo"][:, None]) & (Xq[None] <= b["bhi"][:, None]), axis=2)  # (leaves, N)
        used = inside.any(1)
        sels, parts = [], []
        for j, lf in enumerate(self.leaves):
            if not used[j]:
                lf.cand = None  # its columns are not wanted any more
                continue
            sel = np.flatnonzero(inside[j])
            if not lf.active:
                self._activate(lf)
            c, pos = self._cand_columns(lf, ids[sel], Xq[sel])
            sels.append(sel)
            parts.append(c.blend if pos is None else c.blend[pos])
        # per point: sum_e w_e r_e, sum_e w_e, sum_e w_e v_e, sum_e (dw_e r_e + w_e dr_e), sum_e dw_e
        acc = np.zeros((N, 3 + 2 * d))
        if sels:
            np.add.at(acc, np.concatenate(sels), np.vstack(parts))
        num, wsum, vnum = acc[:, 0], np.maximum(acc[:, 1], 1e-300), acc[:, 2]
        gnum, gw = acc[:, 3: 3 + d], acc[:, 3 + d:]
        return (mean_a + num / wsum, np.maximum(np.minimum(var_a, vnum / wsum), 0.0),
                grad_a + gnum / wsum[:, None] - (num / wsum ** 2)[:, None] * gw)

    def _query_ids(self, Xq: np.ndarray) -> np.ndarray:
        """An id per point: the previous call's id for the same coordinates, else a new one."""
        old, new = self._qids, {}
        ids = np.empty(len(Xq), np.int64)
        for i, row in enumerate(Xq):
            key = row.tobytes()
            q = new.get(key)
            if q is None:
                q = old.get(key)
                if q is None:
                    q = self._next_qid
                    self._next_qid += 1
                new[key] = q
            ids[i] = q
        self._qids = new
        return ids

    def _anchor_at(self, Xq: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Anchor mean, mean gradient and (capping) variance at the points, as in ``predict``
        (kept per point id until the next anchor commit)."""
        N, d = Xq.shape
        mean_a, grad_a, var_a = np.empty(N), np.empty((N, d)), np.empty(N)
        todo = np.ones(N, bool)
        if self._anchor_q is not None and self._anchor_q[0] == self._anchor_rev:
            _, cids, cm, cg, cv = self._anchor_q
            pos, found = _match(cids, ids)
            mean_a[found], grad_a[found], var_a[found] = cm[pos[found]], cg[pos[found]], cv[pos[found]]
            todo = ~found
        if todo.any():
            P = Xq[todo]
            n = len(P)
            Xg, tg = gradient_rows(P)
            mg = self._mu_a(np.vstack([P, Xg]), np.r_[np.full(n, VALUE), tg])
            mean_a[todo], grad_a[todo] = mg[:n], mg[n:].reshape(n, d)
            var_a[todo] = self._anchor_var(P)
        self._anchor_q = (self._anchor_rev, ids, mean_a, grad_a, var_a)
        return mean_a, grad_a, var_a

    def _cand_columns(self, lf: _Leaf, ids: np.ndarray, P: np.ndarray) -> tuple[_CandCache, np.ndarray]:
        """The expert's cache brought up to date for the points (ids, P), and each point's column."""
        gp, d, k0 = lf.gp, self.dim, self._k0
        c = lf.cand if lf.cand is not None and lf.cand.uid == gp.uid else None
        if c is not None:
            if c.n == gp.n and c.rev == gp.rev and len(c.ids) == len(ids) and np.array_equal(c.ids, ids):
                return c, None  # the same points, nothing changed: the last call's values
            pos, keep = _match(c.ids, ids)
            if keep.all() and c.n == gp.n and c.rev == gp.rev:
                return c, pos  # nothing changed: the last call's values
            c = c.take(pos[keep])  # only the columns still wanted
            changed = c.n != gp.n or c.rev != gp.rev
            if c.n < gp.n and len(c.ids):  # rows appended since: the new rows of W
                n0, g = c.n, np.flatnonzero(c.g_ok)
                gcols = (g[:, None] * d + np.arange(d)).ravel()
                Xg, tg = gradient_rows(c.P[g])
                K2 = cross_cov(self.kernel, gp.X[n0:], gp.t[n0:], np.vstack([c.P, Xg]),
                               np.r_[np.full(len(c.ids), VALUE), tg])
                R = gp.L.rows(n0, gp.n)
                W2 = solve_triangular(R[:, n0:], K2 - R[:, :n0] @ np.hstack([c.Wv, c.Wg[:, gcols]]),
                                      lower=True, check_finite=False)
                Wg = np.zeros((gp.n, c.Wg.shape[1]))
                Wg[:n0] = c.Wg
                Wg[n0:, gcols] = W2[:, len(c.ids):]
                c.Wv, c.Wg = np.vstack([c.Wv, W2[:, : len(c.ids)]]), Wg
            c.n = gp.n
            if changed and len(c.ids):
                miss = np.flatnonzero(~c.g_ok)  # asked for again on a changed expert: keep Wg from now on
                if len(miss):
                    Xg, tg = gradient_rows(c.P[miss])
                    c.Wg[:, (miss[:, None] * d + np.arange(d)).ravel()] = gp.solve(
                        cross_cov(self.kernel, gp.X, gp.t, Xg, tg))
                    c.g_ok[:] = True
                c.r = c.Wv.T @ gp.beta
                c.dr = (c.Wg.T @ gp.beta).reshape(-1, d)
                c.v = k0 - np.einsum("ij,ij->j", c.Wv, c.Wv)
                c._blend = None
            c.rev = gp.rev
            new = ~keep
        else:
            keep, new = np.zeros(len(ids), bool), np.ones(len(ids), bool)
        Pn = P[new]
        nq = len(Pn)
        w, dw = lf.weight(Pn, grad=True)
        if gp.n and nq:
            Xg, tg = gradient_rows(Pn)
            KK = cross_cov(self.kernel, gp.X, gp.t, np.vstack([Pn, Xg]), np.r_[np.full(nq, VALUE), tg])
            Wv = gp.solve(KK[:, :nq])
            r, dr = Wv.T @ gp.beta, (KK[:, nq:].T @ gp.alpha).reshape(nq, d)
            v = k0 - np.einsum("ij,ij->j", Wv, Wv)
        else:
            Wv, r, dr, v = np.zeros((gp.n, nq)), np.zeros(nq), np.zeros((nq, d)), np.full(nq, k0)
        fresh = _CandCache(gp.uid, gp.n, gp.rev, ids[new], Pn, w, dw, Wv, np.zeros((gp.n, nq * d)),
                           np.zeros(nq, bool) if gp.n else np.ones(nq, bool), r, dr, v)
        if c is None or not len(c.ids):
            lf.cand = fresh
            return fresh, np.arange(nq)
        lf.cand = _CandCache(gp.uid, gp.n, gp.rev, np.r_[c.ids, fresh.ids], np.vstack([c.P, fresh.P]),
                             np.r_[c.w, fresh.w], np.vstack([c.dw, fresh.dw]), np.hstack([c.Wv, fresh.Wv]),
                             np.hstack([c.Wg, fresh.Wg]), np.r_[c.g_ok, fresh.g_ok], np.r_[c.r, fresh.r],
                             np.vstack([c.dr, fresh.dr]), np.r_[c.v, fresh.v])
        pos = np.empty(len(ids), np.int64)
        pos[np.flatnonzero(keep)] = np.arange(len(c.ids))
        pos[np.flatnonzero(new)] = len(c.ids) + np.arange(nq)
        return lf.cand, pos


def _match(cache_ids: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position of each id in cache_ids (unordered, distinct) and whether it is there."""
    if not len(cache_ids):
        return np.zeros(len(ids), np.int64), np.zeros(len(ids), bool)
    order = np.argsort(cache_ids, kind="stable")
    j = np.minimum(np.searchsorted(cache_ids[order], ids), len(cache_ids) - 1)
    found = cache_ids[order[j]] == ids
    return order[j], found
