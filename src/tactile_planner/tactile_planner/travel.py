"""Travel costs from one start node to every candidate: LMDP (Todorov) and Dijkstra backends.

Candidates are terminal states B, each joined by one edge to its pre-touch
node; the free lattice nodes are the interior I.

LMDP. Symmetric weights W_ij = exp(−rate·ℓ_ij) (edge length ℓ in metres, also
for the terminal edges), degree D_i = number of neighbours (lattice +
terminals). Per step the walk moves with D⁻¹W, i.e. passive dynamics
P = W/ΣW with state cost q_i = −log(Σ_j W_ij / D_i) ≥ rate·(shortest step).
With A = I − D⁻¹W_II, the desirability of candidate b seen from x₀ is
exp(−C(x₀→b)) = (yᵀ D⁻¹ W_IB)_b where Aᵀy = e_x₀. Writing u = D⁻¹y gives the
symmetric positive definite system (D − W_II) u = e_x₀ and
exp(−C_b) = u[node_b]·W_b: ONE solve for all candidates (2D: sparse LU;
3D: Jacobi-preconditioned CG). rate·L* ≤ C_b ≤ rate·L* + h·log(D_max), L* the
shortest path length and h its number of steps, so C/rate → L* as the rate grows.
The expected length of the optimal controlled paths is ∂C_b/∂rate (one more
solve with the same matrix); it is reported as ``travel_m``.

Numerics: the rate is scaled down (``rate_eff``) so that rate_eff × lattice
diagonal ≤ ``max_rate_nats``; u is then within float range across the whole
lattice and costs are taken as −log of positive numbers (log domain).

The desirability of the chosen target b is z = W_b·(D − W_II)⁻¹ e_{node_b};
the path follows the optimal controlled transition u*(x'|x) ∝ P(x'|x) z(x')
greedily (z strictly increases along it, so it cannot loop).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csg
import scipy.sparse.linalg as spla

from .graph import FreeSpaceGraph


class TravelError(RuntimeError):
    """A travel-cost solve that failed (solver did not converge, ...)."""


@dataclass
class TravelSolution:
    """Costs from the start node to every candidate (inf = unreachable).

    Attributes:
        cost: backend cost (LMDP: nats, −log desirability; Dijkstra: metres).
        travel_m: path length estimate (m) to each candidate's pre-touch point.
    """

    cost: np.ndarray
    travel_m: np.ndarray
    start: int
    _path: object = field(repr=False, default=None)

    def path_nodes(self, b: int) -> np.ndarray:
        """Graph nodes from the start node to the pre-touch node of candidate ``b``."""
        return self._path(b)


def _terminal_degree(graph: FreeSpaceGraph, term_node: np.ndarray) -> np.ndarray:
    deg = np.diff(graph.length_m.indptr).astype(np.float64)
    ok = term_node >= 0
    return deg + np.bincount(term_node[ok], minlength=graph.n_nodes)


class LmdpBackend:
    """First-exit LMDP travel costs (see the module docstring)."""

    name = "lmdp"

    def __init__(self, cost_rate_per_m: float, max_rate_nats: float = 60.0, solver: str = "auto",
                 cg_rtol: float = 1e-12, cg_maxiter: int = 5000) -> None:
        if cost_rate_per_m <= 0 or max_rate_nats <= 0:
            raise ValueError("cost_rate_per_m and max_rate_nats must be positive")
        if solver not in ("auto", "lu", "cg"):
            raise ValueError(f"solver must be auto, lu or cg, got '{solver}'")
        self.cost_rate_per_m = float(cost_rate_per_m)
        self.max_rate_nats = float(max_rate_nats)
        self.solver = solver
        self.cg_rtol = cg_rtol
        self.cg_maxiter = cg_maxiter

    def effective_rate(self, graph: FreeSpaceGraph) -> float:
        """rate scaled so that rate × lattice diagonal ≤ max_rate_nats."""
        lat = graph.lattice
        diag = float(np.linalg.norm([a[-1] - a[0] for a in lat.axes]))
        return min(self.cost_rate_per_m, self.max_rate_nats / max(diag, 1e-9))

    def system(self, graph: FreeSpaceGraph, term_node: np.ndarray, rate: float):
        """(D − W_II) as CSR, and W of the terminal edges given their lengths."""
        w = graph.length_m.copy()
        w.data = np.exp(-rate * w.data)
        deg = _terminal_degree(graph, term_node)
        return (sp.diags(deg) - w).tocsr(), w

    def _solver(self, mat: sp.csr_matrix, dim: int):
        kind = self.solver if self.solver != "auto" else ("lu" if dim == 2 else "cg")
        if kind == "lu":
            lu = spla.splu(mat.tocsc())
            return lu.solve
        inv_diag = 1.0 / mat.diagonal()
        pre = spla.LinearOperator(mat.shape, matvec=lambda x: inv_diag * x, dtype=np.float64)

        def solve(rhs: np.ndarray) -> np.ndarray:
            x, info = spla.cg(mat, rhs, rtol=self.cg_rtol, atol=0.0, maxiter=self.cg_maxiter, M=pre)
            if info != 0:
                raise TravelError(f"conjugate gradients did not converge (info={info})")
            return x

        return solve

    def solve(self, graph: FreeSpaceGraph, start: int, term_node: np.ndarray,
              term_len_m: np.ndarray, reachable: np.ndarray) -> TravelSolution:
        """Costs to every candidate with ``reachable`` (others: inf)."""
        rate = self.effective_rate(graph)
        tn = np.where(reachable, term_node, -1)
        mat, w = self.system(graph, tn, rate)
        solve = self._solver(mat, graph.lattice.dim)
        e0 = np.zeros(graph.n_nodes)
        e0[start] = 1.0
        u = solve(e0)
        # d(D − W)/d rate = ℓ∘W  ⇒  du/d rate = −(D − W)⁻¹ (ℓ∘W) u
        lw = graph.length_m.multiply(w).tocsr()
        du = -solve(lw @ u)
        cost = np.full(len(term_node), np.inf)
        travel = np.full(len(term_node), np.inf)
        ok = reachable & (tn >= 0)
        un = u[tn[ok]]
        good = un > 0
        idx = np.flatnonzero(ok)
        cost[idx[good]] = -np.log(un[good]) + rate * term_len_m[idx[good]]
        travel[idx[good]] = -du[tn[idx[good]]] / un[good] + term_len_m[idx[good]]
        indptr, indices = w.indptr, w.indices

        def path(b: int) -> np.ndarray:
            target = tn[b]
            e = np.zeros(graph.n_nodes)
            e[target] = 1.0
            z = solve(e) * np.exp(-rate * term_len_m[b])
            w_term = np.exp(-rate * term_len_m[b])
            nodes = [start]
            cur = start
            for _ in range(graph.n_nodes):
                nb = indices[indptr[cur]:indptr[cur + 1]]
                val = w.data[indptr[cur]:indptr[cur + 1]] * z[nb]
                best = int(np.argmax(val)) if len(nb) else -1
                if cur == target and (best < 0 or w_term >= val[best]):
                    return np.array(nodes)
                if best < 0 or z[nb[best]] <= z[cur] and cur != target:
                    break  # no ascent: numerical plateau
                cur = int(nb[best])
                nodes.append(cur)
            # fall back to the shortest path (never expected; kept for robustness)
            _, pred = csg.dijkstra(graph.length_m, indices=start, return_predecessors=True)
            return _unwind(pred, start, target)

        return TravelSolution(cost=cost, travel_m=travel, start=start, _path=path)


def _unwind(pred: np.ndarray, start: int, target: int) -> np.ndarray:
    nodes = [target]
    while nodes[-1] != start:
        p = pred[nodes[-1]]
        if p < 0:
            raise TravelError("target not reachable from the start node")
        nodes.append(int(p))
    return np.array(nodes[::-1])


class DijkstraBackend:
    """Shortest-path travel costs (metres) with scipy.sparse.csgraph.dijkstra."""

    name = "dijkstra"

    def solve(self, graph: FreeSpaceGraph, start: int, term_node: np.ndarray,
              term_len_m: np.ndarray, reachable: np.ndarray) -> TravelSolution:
        dist, pred = csg.dijkstra(graph.length_m, indices=start, return_predecessors=True)
        ok = reachable & (term_node >= 0)
        cost = np.full(len(term_node), np.inf)
        cost[ok] = dist[term_node[ok]] + term_len_m[ok]
        tn = term_node
        return TravelSolution(cost=cost, travel_m=cost.copy(), start=start,
                              _path=lambda b: _unwind(pred, start, int(tn[b])))


def make_backend(name: str, cost_rate_per_m: float, max_rate_nats: float, solver: str = "auto",
                 cg_rtol: float = 1e-12):
    """'lmdp' or 'dijkstra'."""
    if name == "lmdp":
        return LmdpBackend(cost_rate_per_m, max_rate_nats, solver, cg_rtol)
    if name == "dijkstra":
        return DijkstraBackend()
    raise ValueError(f"backend must be 'lmdp' or 'dijkstra', got '{name}'")
