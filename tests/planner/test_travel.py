"""LMDP travel costs against independent references (dense per-candidate solves, Dijkstra)."""

import numpy as np
import pytest
import scipy.sparse.csgraph as csg

from tactile_planner.graph import build_free_graph
from tactile_planner.maps import MapLattice
from tactile_planner.travel import DijkstraBackend, LmdpBackend


def lattice_2d(n=24, obstacle=True, extent=0.3):
    """n×n lattice over [0, extent]²; obstacle: a disc (SDF) of radius 0.06 m at the centre."""
    ax = np.linspace(0.0, extent, n)
    gx, gy = np.meshgrid(ax, ax, indexing="ij")
    sdf = np.hypot(gx - extent / 2, gy - extent / 2) - (0.06 if obstacle else -1.0)
    return MapLattice((ax, ax), sdf, np.full(sdf.shape, 1e-4), 0.06)


def some_terminals(graph, k, seed):
    rng = np.random.default_rng(seed)
    nodes = rng.choice(graph.n_nodes, size=k, replace=False)
    return nodes, rng.uniform(0.0, 0.01, size=k)


def dense_first_exit_costs(graph, start, term_node, term_len, rate):
    """Independent reference: one dense first-exit solve PER candidate.

    P(i→j) = exp(−rate ℓ_ij)/deg_i over lattice neighbours and attached terminals;
    z_I = (I − P_II)⁻¹ P_Ib  (terminal b: z = 1, other terminals: z = 0).
    """
    n = graph.n_nodes
    ell = graph.length_m.toarray()
    w = np.where(ell > 0, np.exp(-rate * ell), 0.0)
    deg = (ell > 0).sum(axis=1) + np.bincount(term_node, minlength=n)
    p_ii = w / deg[:, None]
    out = []
    for b in range(len(term_node)):
        p_ib = np.zeros(n)
        p_ib[term_node[b]] = np.exp(-rate * term_len[b]) / deg[term_node[b]]
        z = np.linalg.solve(np.eye(n) - p_ii, p_ib)
        out.append(-np.log(z[start]))
    return np.array(out)


@pytest.mark.parametrize("solver", ["lu", "cg"])
@pytest.mark.parametrize("obstacle", [False, True])
def test_one_solve_equals_per_candidate_solves(solver, obstacle):
    graph = build_free_graph(lattice_2d(16, obstacle), margin_m=0.0)
    nodes, lens = some_terminals(graph, 12, seed=1)
    # LU is accurate at any rate; CG within its (default) rate budget
    backend = LmdpBackend(cost_rate_per_m=40.0, max_rate_nats=1e9, solver=solver)
    start = 0
    sol = backend.solve(graph, start, nodes, lens, np.ones(len(nodes), bool))
    want = dense_first_exit_costs(graph, start, nodes, lens, backend.effective_rate(graph))
    if solver == "lu":
        np.testing.assert_allclose(sol.cost, want, rtol=0, atol=1e-8)
    else:
        # CG is accurate relative to max(u) (rtol 1e-12): ~1e-5 nats 20 nats below it; costs
        # beyond its range are reported and replaced by an upper bound (the best single path)
        n_far = backend.last_info["n_beyond_range"]
        assert n_far <= 2
        assert np.count_nonzero(np.abs(sol.cost - want) > 1e-4) == n_far
        assert np.all(sol.cost >= want - 1e-4)


@pytest.mark.parametrize("obstacle", [False, True])
def test_lmdp_tends_to_shortest_path_and_orders_like_dijkstra(obstacle):
    graph = build_free_graph(lattice_2d(24, obstacle), margin_m=0.0)
    nodes, _ = some_terminals(graph, 40, seed=2)
    lens = np.zeros(len(nodes))
    start = graph.nearest_node(np.array([0.0, 0.0, 0.06]))
    reach = np.ones(len(nodes), bool)
    # independent shortest paths (metres) and step counts
    dist, pred = csg.dijkstra(graph.length_m, indices=start, return_predecessors=True)
    shortest = dist[nodes]
    res = float(np.min(graph.lattice.spacing_m))
    d_max = float(np.diff(graph.length_m.indptr).max() + np.bincount(nodes).max())
    np.testing.assert_allclose(DijkstraBackend().solve(graph, start, nodes, lens, reach).cost, shortest)
    gaps = []
    for rate in (100.0, 1000.0, 10000.0):
        c = LmdpBackend(rate, max_rate_nats=1e9, solver="lu").solve(graph, start, nodes, lens, reach).cost
        # rate·L* ≤ C ≤ rate·L* + h·log(D_max), h ≤ L*/res steps
        assert np.all(c >= rate * shortest - 1e-6)
        assert np.all(c <= rate * shortest + (shortest / res + 1) * np.log(d_max) + 1e-6)
        gaps.append(np.max(c / rate - shortest))
        # ordering: pairs whose shortest paths differ by more than the bound's slack agree
        slack = (shortest / res + 1) * np.log(d_max) / rate
        i, j = np.triu_indices(len(nodes), 1)
        clear = np.abs(shortest[i] - shortest[j]) > slack[i] + slack[j]
        assert np.all(np.sign(c[i] - c[j])[clear] == np.sign(shortest[i] - shortest[j])[clear])
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 0.01 * res * 60  # 60 steps × log(D)/rate ≪ a lattice step


@pytest.mark.parametrize("obstacle", [False, True])
def test_lmdp_at_a_moderate_rate_already_ranks_like_dijkstra(obstacle):
    """Rate 300/m, where the bounds above are loose: the rank correlation with the shortest paths."""
    graph = build_free_graph(lattice_2d(24, obstacle), margin_m=0.0)
    nodes, _ = some_terminals(graph, 40, seed=2)
    start = graph.nearest_node(np.array([0.0, 0.0, 0.06]))
    shortest = csg.dijkstra(graph.length_m, indices=start)[nodes]
    c = LmdpBackend(300.0, max_rate_nats=1e9, solver="lu").solve(
        graph, start, nodes, np.zeros(len(nodes)), np.ones(len(nodes), bool)).cost

    def rank(v):
        return np.argsort(np.argsort(v))

    assert np.corrcoef(rank(c), rank(shortest))[0, 1] > 0.95


def test_no_underflow_across_the_largest_2d_lattice():
    """128² lattice, start in one corner, candidates in the far corner: finite costs within the bounds."""
    graph = build_free_graph(lattice_2d(128, True), margin_m=0.015)
    start = graph.nearest_node(np.array([0.0, 0.0, 0.06]))
    far = graph.attach(np.array([[0.3, 0.3, 0.06], [0.3, 0.29, 0.06], [0.0, 0.3, 0.06]]))[0]
    backend = LmdpBackend(cost_rate_per_m=1e6, max_rate_nats=60.0, solver="lu")
    sol = backend.solve(graph, start, far, np.zeros(3), np.ones(3, bool))
    rate = backend.effective_rate(graph)
    shortest = csg.dijkstra(graph.length_m, indices=start)[far]
    assert np.all(np.isfinite(sol.cost))
    assert np.all(sol.cost >= rate * shortest - 1e-6)
    assert np.all(sol.cost <= rate * shortest + (shortest / 0.3 * 127 + 1) * np.log(9.0))
    assert np.all(np.isfinite(sol.travel_m)) and np.all(sol.travel_m >= shortest - 1e-9)
    assert len(sol.path_nodes(0)) > 100


def test_no_underflow_3d_shell_cg_matches_lu():
    """48³ shell around a sphere, CG (3D default) vs LU: every cost finite and equal."""
    ax = np.linspace(0.0, 0.3, 48)
    g = np.meshgrid(ax, ax, ax, indexing="ij")
    sdf = np.sqrt(sum((gi - 0.15) ** 2 for gi in g)) - 0.06
    lat = MapLattice((ax, ax, ax), sdf, np.full(sdf.shape, 1e-4), None)
    graph = build_free_graph(lat, margin_m=0.015, shell_m=0.02, min_z_m=0.0)
    r = 0.06 + 0.025  # mid-shell; the antipode is the longest path on the shell
    start = graph.nearest_node(np.array([0.15 - r, 0.15, 0.15]))
    far = graph.attach(np.array([[0.15 + r, 0.15, 0.15], [0.15, 0.15, 0.15 + r], [0.15, 0.15 - r, 0.15]]))[0]
    assert np.all(far >= 0)
    reach = np.ones(3, bool)
    cg = LmdpBackend(1e6, solver="cg")
    lu = LmdpBackend(1e6, solver="lu", max_rate_nats=cg.cg_max_rate_nats)
    c_cg = cg.solve(graph, start, far, np.zeros(3), reach).cost
    assert cg.last_info["n_beyond_range"] == 0
    c_lu = lu.solve(graph, start, far, np.zeros(3), reach).cost
    assert np.all(np.isfinite(c_cg))
    np.testing.assert_allclose(c_cg, c_lu, atol=1e-4)


@pytest.mark.parametrize("backend", [LmdpBackend(300.0, solver="lu"), LmdpBackend(300.0, solver="cg"), DijkstraBackend()])
def test_lattice_paths_run_along_edges_from_start_to_the_pretouch_node(backend):
    graph = build_free_graph(lattice_2d(32, True), margin_m=0.01)
    nodes, lens = some_terminals(graph, 10, seed=3)
    start = graph.nearest_node(np.array([0.0, 0.15, 0.06]))
    sol = backend.solve(graph, start, nodes, lens, np.ones(10, bool))
    adj = graph.length_m.toarray() > 0
    for b in range(10):
        path = sol.path_nodes(b)
        assert path[0] == start and path[-1] == nodes[b]
        assert np.all(adj[path[:-1], path[1:]])  # every step is a free-graph edge
        assert len(set(path.tolist())) == len(path)  # no loops
    assert not getattr(backend, "last_info", {}).get("path_fallback")


@pytest.mark.parametrize("obstacle", [False, True])
def test_the_path_at_a_high_rate_is_a_shortest_path(obstacle):
    """The path (u ascended from the target, reversed) against Dijkstra's shortest length: as the
    rate grows the controlled walk concentrates on shortest paths, round the disc too."""
    graph = build_free_graph(lattice_2d(32, obstacle), margin_m=0.01)
    nodes, lens = some_terminals(graph, 15, seed=4)
    start = graph.nearest_node(np.array([0.0, 0.0, 0.06]))
    backend = LmdpBackend(cost_rate_per_m=3000.0, max_rate_nats=300.0, solver="lu")  # no underflow
    sol = backend.solve(graph, start, nodes, lens, np.ones(len(nodes), bool))
    shortest = csg.dijkstra(graph.length_m, indices=start)[nodes]
    for b in range(len(nodes)):
        path = sol.path_nodes(b)
        length = sum(graph.length_m[i, j] for i, j in zip(path[:-1], path[1:]))
        assert length == pytest.approx(shortest[b], rel=1e-9, abs=1e-12)
    assert not backend.last_info.get("path_fallback")


def test_travel_length_shortest_is_the_octile_distance_on_an_empty_lattice():
    """No obstacle: the shortest 8-connected path between lattice nodes has a closed form,
    h·(max(|di|, |dj|) + (√2 − 1)·min(|di|, |dj|)); travel_m adds the terminal edge."""
    lat = lattice_2d(20, obstacle=False)
    graph = build_free_graph(lat, margin_m=0.0)
    h = float(lat.axes[0][1] - lat.axes[0][0])
    ij = np.round(graph.xyz[:, :2] / h).astype(int)
    nodes, lens = some_terminals(graph, 15, seed=3)
    start = int(np.flatnonzero((ij[:, 0] == 4) & (ij[:, 1] == 7))[0])
    sol = LmdpBackend(cost_rate_per_m=40.0, solver="lu", travel_length="shortest").solve(
        graph, start, nodes, lens, np.ones(15, bool))
    d = np.abs(ij[nodes] - ij[start])
    want = h * (d.max(axis=1) + (np.sqrt(2.0) - 1.0) * d.min(axis=1)) + lens
    np.testing.assert_allclose(sol.travel_m, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("solver", ["lu", "cg"])
def test_travel_length_expected_is_the_rate_derivative_of_the_cost(solver):
    """travel_length='expected': travel_m = ∂C/∂rate, against central finite differences of two
    cost solves at rate ± δ (the effective rate is below the budget: it is the rate given)."""
    graph = build_free_graph(lattice_2d(16, True), margin_m=0.0)
    nodes, lens = some_terminals(graph, 10, seed=5)
    rate, delta = 5.0, 1e-3  # CG: 5 × the 0.42 m diagonal is within its 3-nat budget
    costs = []
    for r in (rate - delta, rate + delta):
        costs.append(LmdpBackend(cost_rate_per_m=r, max_rate_nats=1e9, solver="lu").solve(
            graph, 0, nodes, lens, np.ones(10, bool), want_travel_m=False).cost)
    fd = (costs[1] - costs[0]) / (2 * delta)
    sol = LmdpBackend(cost_rate_per_m=rate, max_rate_nats=1e9, solver=solver, travel_length="expected").solve(
        graph, 0, nodes, lens, np.ones(10, bool))
    np.testing.assert_allclose(sol.travel_m, fd, rtol=1e-5)
    shortest = csg.dijkstra(graph.length_m, indices=0)[nodes] + lens
    assert np.all(sol.travel_m >= shortest - 1e-9)  # the controlled walk is never shorter


def test_unknown_travel_length_is_refused():
    with pytest.raises(ValueError, match="travel_length"):
        LmdpBackend(cost_rate_per_m=10.0, travel_length="longest")
