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
``travel_m``, the path length the motion model turns into robot time, is by default
(``travel_length="expected"``) the expected length of the optimal controlled paths,
∂C_b/∂rate (one more solve with the same matrix). The path the arm is sent — the most
likely path below, shortcut — is shorter: the walk the LMDP averages over is diffusive
at the rates the numerics allow, and ∂C/∂rate is 1.2–1.8× the path sent in 2D and 4–5×
in 3D. ``travel_length="shortest"`` gives the shortest free path's length over the graph
instead (Dijkstra plus the terminal edge; the path sent is 0.71–0.95× of it) and skips
the second solve, but the decisions it times are worse on the generated suites
(docs/planner.md, *Travel length*).

Numerics: the rate is scaled down (``rate_eff``) so that rate_eff × lattice
diagonal of the graph's bounding box ≤ ``max_rate_nats``; with the KL term (≤ log D per step) the
largest cost across a 128² (2D) or 48³ (3D) lattice then stays far above
float underflow (e^−708), and costs are taken as −log of positive numbers.
The sparse LU of this M-matrix needs no pivoting and its triangular solves
add positive terms only, so every entry of u is accurate relative to itself.
Conjugate gradients (3D default: fast) is accurate only relative to max(u),
so with CG the rate budget is ``cg_max_rate_nats`` (default 3, rtol 1e-14:
on a 48³ shell every cost, antipode included, matches LU to < 1e-4 nats);
candidates whose u falls below 1e3·rtol·max(u) are reported
(``last_info['n_beyond_range']``) and get the single-best-path LMDP cost
(an upper bound, Dijkstra with step cost rate·ℓ + log D) and the shortest
path length instead.

The path to the chosen target b needs no second solve. With symmetric W, a path's
weight under the controlled walk, Π W_ij/D_i, is the same both ways up to the end
points' degrees, so the most likely path from x₀ to b is the reversed most likely path
from b to x₀, whose desirability is G(·, x₀) = u. The path walks from b greedily up
W_xx'·u(x') (the controlled transition towards x₀) and is reversed; u strictly
increases along it, so it cannot loop, and it ends at x₀.
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
    """Neighbours (lattice + terminals) per node; an isolated node counts 1 (it has no
    transitions either way) so that D − W stays non-singular: its row then reads u_i = e_i."""
    deg = np.diff(graph.length_m.indptr).astype(np.float64)
    ok = term_node >= 0
    return np.maximum(deg + np.bincount(term_node[ok], minlength=graph.n_nodes), 1.0)


#: what ``travel_m`` holds: the LMDP's expected path length ∂C/∂rate, or the shortest free path's length
TRAVEL_LENGTHS = ("expected", "shortest")


class LmdpBackend:
    """First-exit LMDP travel costs (see the module docstring)."""

    name = "lmdp"

    def __init__(self, cost_rate_per_m: float, max_rate_nats: float = 60.0, solver: str = "auto",
                 cg_rtol: float = 1e-14, cg_maxiter: int = 5000, cg_max_rate_nats: float = 3.0,
                 travel_length: str = "expected") -> None:
        if cost_rate_per_m <= 0 or max_rate_nats <= 0:
            raise ValueError("cost_rate_per_m and max_rate_nats must be positive")
        if solver not in ("auto", "lu", "cg"):
            raise ValueError(f"solver must be auto, lu or cg, got '{solver}'")
        if travel_length not in TRAVEL_LENGTHS:
            raise ValueError(f"travel_length must be one of {TRAVEL_LENGTHS}, got '{travel_length}'")
        self.travel_length = travel_length
        self.cost_rate_per_m = float(cost_rate_per_m)
        self.max_rate_nats = float(max_rate_nats)
        self.solver = solver
        self.cg_rtol = cg_rtol
        self.cg_maxiter = cg_maxiter
        self.cg_max_rate_nats = float(cg_max_rate_nats)
        self.last_info: dict = {}

    def solver_kind(self, dim: int) -> str:
        return self.solver if self.solver != "auto" else ("lu" if dim == 2 else "cg")

    def effective_rate(self, graph: FreeSpaceGraph) -> float:
        """rate scaled so that rate × diagonal of the graph's bounding box ≤ max_rate_nats
        (CG: cg_max_rate_nats)."""
        diag = float(np.linalg.norm(np.ptp(graph.xyz, axis=0))) if graph.n_nodes else 1.0
        budget = self.cg_max_rate_nats if self.solver_kind(graph.lattice.dim) == "cg" else self.max_rate_nats
        return min(self.cost_rate_per_m, budget / max(diag, 1e-9))

    def system(self, graph: FreeSpaceGraph, term_node: np.ndarray, rate: float):
        """(D − W_II) as CSR, and W of the terminal edges given their lengths."""
        w = graph.length_m.copy()
        w.data = np.exp(-rate * w.data)
        deg = _terminal_degree(graph, term_node)
        return (sp.diags(deg) - w).tocsr(), w

    def _solver(self, mat: sp.csr_matrix, dim: int):
        kind = self.solver_kind(dim)
        if kind == "lu":
            # SPD M-matrix: no pivoting needed; the triangular solves add positive terms only
            # (no cancellation), so every entry of u is accurate relative to itself.
            lu = spla.splu(mat.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options=dict(SymmetricMode=True))
            return lu.solve, kind
        inv_diag = 1.0 / mat.diagonal()
        pre = spla.LinearOperator(mat.shape, matvec=lambda x: inv_diag * x, dtype=np.float64)

        def solve(rhs: np.ndarray) -> np.ndarray:
            x, info = spla.cg(mat, rhs, rtol=self.cg_rtol, atol=0.0, maxiter=self.cg_maxiter, M=pre)
            if info != 0:
                raise TravelError(f"conjugate gradients did not converge (info={info})")
            return x

        return solve, kind

    def solve(self, graph: FreeSpaceGraph, start: int, term_node: np.ndarray,
              term_len_m: np.ndarray, reachable: np.ndarray, want_travel_m: bool = True) -> TravelSolution:
        """Costs to every candidate with ``reachable`` (others: inf).

        ``want_travel_m=False`` skips the path lengths (``travel_m`` is then NaN).
        """
        self.last_info = {}
        rate = self.effective_rate(graph)
        tn = np.where(reachable, term_node, -1)
        mat, w = self.system(graph, tn, rate)
        solve, kind = self._solver(mat, graph.lattice.dim)
        e0 = np.zeros(graph.n_nodes)
        e0[start] = 1.0
        u = solve(e0)
        expected = want_travel_m and self.travel_length == "expected"
        if expected:  # d(D − W)/d rate = ℓ∘W  ⇒  du/d rate = −(D − W)⁻¹ (ℓ∘W) u
            du = -solve(graph.length_m.multiply(w).tocsr() @ u)
        cost = np.full(len(term_node), np.inf)
        travel = np.full(len(term_node), np.inf)
        ok = reachable & (tn >= 0)
        idx = np.flatnonzero(ok)
        un = u[tn[idx]]
        # CG is accurate only relative to max(u): below this floor an entry is noise
        floor = 0.0 if kind == "lu" else 1e3 * self.cg_rtol * float(np.max(np.abs(u)))
        good = un > floor
        gi, far = idx[good], idx[~good]
        # the shortest free path length from the start to every node (m), where it is needed
        if (want_travel_m and not expected) or len(far):
            dist = csg.dijkstra(graph.length_m, indices=start)
        cost[gi] = -np.log(un[good]) + rate * term_len_m[gi]
        if not want_travel_m:
            travel[gi] = np.nan
        elif expected:
            travel[gi] = -du[tn[gi]] / un[good] + term_len_m[gi]
        else:
            travel[gi] = dist[tn[gi]] + term_len_m[gi]
        if len(far):
            # beyond the iterative solver's dynamic range: the single best path's LMDP cost
            # (an upper bound: rate·ℓ + log D per step) and its length
            deg = mat.diagonal()
            lc = graph.length_m.tocoo()
            wt = rate * lc.data + 0.5 * (np.log(deg[lc.row]) + np.log(deg[lc.col]))
            phi = csg.dijkstra(sp.csr_matrix((wt, (lc.row, lc.col)), shape=mat.shape), indices=start)
            bound = phi[tn[far]] + np.log(deg[tn[far]]) + rate * term_len_m[far]
            cmax = float(np.max(cost[gi])) if len(gi) else 0.0
            cost[far] = np.maximum(bound, cmax)
            travel[far] = dist[tn[far]] + term_len_m[far]
        self.last_info.update(solver=kind, rate_per_m=rate, n_beyond_range=int(len(far)),
                              travel_length=self.travel_length)
        indptr, indices = w.indptr, w.indices

        def path(b: int) -> np.ndarray:
            # Greedy ascent of u = (D − W_II)⁻¹ e_start from the target, reversed: no further solve.
            # u(x) = G(x, start) rises strictly towards the start (off it, D_x u_x = Σ_y W_xy u_y
            # with W ≤ 1, so the best neighbour holds more), so the walk cannot loop and ends there.
            target = tn[b]
            nodes = [target]
            cur = target
            for _ in range(graph.n_nodes):
                if cur == start:
                    return np.array(nodes[::-1])
                nb = indices[indptr[cur]:indptr[cur + 1]]
                if not len(nb):
                    break
                val = w.data[indptr[cur]:indptr[cur + 1]] * u[nb]
                best = int(np.argmax(val))
                if u[nb[best]] <= max(u[cur], 0.0):
                    break  # no ascent: u below the solver's accuracy here
                cur = int(nb[best])
                nodes.append(cur)
            self.last_info["path_fallback"] = True
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
              term_len_m: np.ndarray, reachable: np.ndarray, want_travel_m: bool = True) -> TravelSolution:
        dist, pred = csg.dijkstra(graph.length_m, indices=start, return_predecessors=True)
        ok = reachable & (term_node >= 0)
        cost = np.full(len(term_node), np.inf)
        cost[ok] = dist[term_node[ok]] + term_len_m[ok]
        tn = term_node
        return TravelSolution(cost=cost, travel_m=cost.copy(), start=start,
                              _path=lambda b: _unwind(pred, start, int(tn[b])))


def make_backend(name: str, cost_rate_per_m: float, max_rate_nats: float, solver: str = "auto",
                 cg_rtol: float = 1e-14, cg_max_rate_nats: float = 3.0, travel_length: str = "expected"):
    """'lmdp' or 'dijkstra' (whose costs are the shortest path lengths: ``travel_length`` does not apply)."""
    if name == "lmdp":
        return LmdpBackend(cost_rate_per_m, max_rate_nats, solver, cg_rtol, cg_max_rate_nats=cg_max_rate_nats,
                           travel_length=travel_length)
    if name == "dijkstra":
        return DijkstraBackend()
    raise ValueError(f"backend must be 'lmdp' or 'dijkstra', got '{name}'")
