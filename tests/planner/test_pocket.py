"""A candidate at the bottom of a slot the estimate shows too narrow for the path margin but wide enough
for the finger (tactile_planner.pocket): entered along its approach axis instead of being unreachable;
free space behind a mouth narrower than the margin: bridged through the mouth, in and out (tactile_planner.graph).
Oracle: the slot's signed distance, computed here from its boxes (not from the planner's clearance)."""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.csgraph as csg
from scipy.ndimage import distance_transform_edt

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE
from tactile_planner.graph import build_free_graph
from tactile_planner.maps import MapLattice
from tactile_planner.planner import TouchPlanner, load_params
from tactile_planner.pocket import closer_pretouch, pocket_entries

CONFIG = Path(__file__).resolve().parents[2] / "src/tactile_planner/config/soc_planner.yaml"
Z = 0.06


def _box_sdf(p, lo, hi):
    c, half = (np.asarray(lo) + hi) / 2, (np.asarray(hi) - lo) / 2
    q = np.abs(p - c) - half
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)


def _slot_sdf(p, half_width_m):
    """A block (x 0.44..0.56, y -0.05..0.035) with a slot x 0.5 ± half_width down to y = 0: the union of
    the base and the two walls (min of box distances: exact outside, where it matters here)."""
    base = _box_sdf(p, [0.44, -0.05], [0.56, 0.0])
    left = _box_sdf(p, [0.44, -0.05], [0.5 - half_width_m, 0.035])
    right = _box_sdf(p, [0.5 + half_width_m, -0.05], [0.56, 0.035])
    return np.minimum(base, np.minimum(left, right))


def _lattice(half_width_m, n=160):
    ax = (np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n))
    X, Y = np.meshgrid(*ax, indexing="ij")
    mean = _slot_sdf(np.stack([X, Y], axis=-1), half_width_m)
    return MapLattice(axes=ax, mean_m=mean, variance_m2=np.full(mean.shape, 1e-6), plane_z_m=Z)


def test_a_pre_touch_point_in_a_slot_is_entered_along_the_normal_keeping_the_finger_clear():
    r_tip, gap, margin, back = 0.01, 0.002, 0.015, 0.03
    lat = _lattice(0.013)  # 26 mm slot: the tip centre has 13 mm in the middle (< margin, > r_tip + gap)
    graph = build_free_graph(lat, margin, 0.03, -np.inf, None, "distance")
    pre = np.array([[0.5, 0.02, Z]])  # the slot bottom's candidate (0.5, 0) + (standoff + r_tip) along +y
    n = np.array([[0.0, 1.0, 0.0]])
    assert graph.attach(pre)[0][0] < 0  # unreachable at the margin: the case
    entry, node, length = pocket_entries(graph, pre, n, back, r_tip + gap)
    assert node[0] >= 0
    t = entry[0, 1] - pre[0, 1]
    np.testing.assert_allclose(entry[0, [0, 2]], pre[0, [0, 2]])  # on the approach axis
    assert 0 < t <= back + 1e-12
    s = np.linspace(0, 1, 200)[:, None]
    seg = pre[0, :2] + s * (entry[0, :2] - pre[0, :2])
    assert _slot_sdf(seg, 0.013).min() >= r_tip + gap - 3e-4  # the finger's clearance (lattice interpolation)
    # the entry joins the graph with a segment at the margin (the graph's clearance is the distance to the
    # lattice's zero crossings: within 1 mm of the true one next to the wall's corner at this lattice step)
    assert _slot_sdf(np.linspace(entry[0, :2], graph.xyz[node[0], :2], 50), 0.013).min() >= margin - 1e-3
    assert length[0] == pytest.approx(np.linalg.norm(graph.xyz[node[0]] - entry[0]))
    # too narrow for the finger (20 mm: 10 mm < r_tip + gap): no entry
    narrow = build_free_graph(_lattice(0.010), margin, 0.03, -np.inf, None, "distance")
    assert pocket_entries(narrow, pre, n, back, r_tip + gap)[1][0] == -1


def _as_map(lattice, cand_xyz, cand_normal):
    X, Y = np.meshgrid(*lattice.axes, indexing="ij")
    grid = np.zeros(X.size, dtype=VARIANCE_MAP_DTYPE)
    grid["x"], grid["y"], grid["z"] = X.ravel(), Y.ravel(), Z
    grid["mean"], grid["variance"], grid["kind"] = lattice.mean_m.ravel(), lattice.variance_m2.ravel(), KIND_LATTICE
    c = np.zeros(len(cand_xyz), dtype=VARIANCE_MAP_DTYPE)
    c["x"], c["y"], c["z"] = cand_xyz.T
    c["normal_x"], c["normal_y"], c["normal_z"] = cand_normal.T
    c["variance"], c["kind"] = 1e-4, KIND_CANDIDATE
    return np.concatenate([grid, c])


@pytest.mark.parametrize("pocket_entry_m, narrow_penalty", [(0.03, 0.0), (0.0, 0.0), (0.0, 3.0)])
def test_the_planner_touches_the_slot_bottom_through_its_entry(pocket_entry_m, narrow_penalty):
    lat = _lattice(0.013)
    cand = np.array([[0.5, 0.0, Z]])
    m = _as_map(lat, cand, np.array([[0.0, 1.0, 0.0]]))
    params = dict(load_params(str(CONFIG)), strategy="uncertainty", search_quantile=0.0, pocket_entry_m=pocket_entry_m,
                  pocket_link_m=pocket_entry_m, narrow_penalty=narrow_penalty)  # all 0: every way into a pocket off
    res = TouchPlanner.from_params(params, seed=0).plan(m, np.array([0.40, 0.10, Z]))
    if pocket_entry_m == 0 and narrow_penalty == 0:
        assert res.status == "all_unreachable" and "no free pre-touch point" in res.message, res.message
        return
    assert res.ok, res.message
    np.testing.assert_allclose(res.pretouch_xyz, [0.5, 0.02, Z], atol=1e-9)
    np.testing.assert_allclose(res.path_xyz[-1], res.pretouch_xyz)
    if pocket_entry_m > 0:
        last = res.path_xyz[-2]  # the entry: straight above, on the approach axis
        assert abs(last[0] - 0.5) < 1e-9 and last[1] > 0.02
    # the whole path keeps the finger off the slot's true walls (skin gap > 0), the graph part the margin
    s = np.linspace(0, 1, 100)[:, None]
    pts = np.vstack([a + s * (b - a) for a, b in zip(res.path_xyz[:-1, :2], res.path_xyz[1:, :2])])
    assert _slot_sdf(pts, 0.013).min() > 0.01


def _bottle_sdf(p):
    """A block (x 0.42..0.58, y -0.05..0.03) hollowed by a cavity (x 0.46..0.54, y -0.03..0.01: 20 mm of
    room for the tip centre in the middle) open through a 26 mm mouth (x 0.5 ± 0.013, y 0.01..0.03): the
    mouth leaves the tip centre 13 mm, less than the path margin, more than the finger needs. max(block,
    −cavity) with the cavity a union of boxes: its zero set is the solid's boundary (what the planner
    reads), its magnitude only a bound of the distance; the oracle of the tests is :func:`_bottle_gap`."""
    block = _box_sdf(p, [0.42, -0.05], [0.58, 0.03])
    cavity = np.minimum(_box_sdf(p, [0.46, -0.03], [0.54, 0.01]), _box_sdf(p, [0.487, 0.0], [0.513, 0.2]))
    return np.maximum(block, -cavity)


_FINE_M = 2.5e-4  # the oracle's raster


def _bottle_gap(p):
    """Distance (m) from points outside the bottle's solid to it: an exact distance transform of the solid
    rasterised at 0.25 mm (independent of the planner's lattice and its zero crossings)."""
    xs, ys = np.arange(0.38, 0.62, _FINE_M), np.arange(-0.09, 0.10, _FINE_M)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    solid = _bottle_sdf(np.stack([X, Y], axis=-1)) <= 0
    dist = distance_transform_edt(~solid, sampling=_FINE_M)
    i = np.clip(np.rint((p[:, 0] - xs[0]) / _FINE_M).astype(int), 0, len(xs) - 1)
    j = np.clip(np.rint((p[:, 1] - ys[0]) / _FINE_M).astype(int), 0, len(ys) - 1)
    return dist[i, j]


def _bottle_lattice(n=160):
    ax = (np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n))
    X, Y = np.meshgrid(*ax, indexing="ij")
    mean = _bottle_sdf(np.stack([X, Y], axis=-1))
    return MapLattice(axes=ax, mean_m=mean, variance_m2=np.full(mean.shape, 1e-6), plane_z_m=Z)


def test_free_space_cut_off_behind_a_narrow_mouth_is_bridged_through_it():
    r_tip, gap, margin = 0.01, 0.002, 0.015
    plain = build_free_graph(_bottle_lattice(), margin, 0.03, -np.inf, None, "distance")
    graph = build_free_graph(_bottle_lattice(), margin, 0.03, -np.inf, None, "distance", r_tip + gap, 0.06)
    inside = np.array([0.5, -0.01, Z])  # the cavity floor's candidate (0.5, -0.03) + 20 mm along +y
    outside = np.array([0.40, 0.10, Z])
    _, comp = csg.connected_components(plain.length_m, directed=False)
    assert comp[plain.nearest_node(inside)] != comp[plain.nearest_node(outside)]  # cut off: the case
    # bridged: the same nodes and edges as before, plus one lattice path through the mouth
    new = ~np.isin(graph.grid_of_node, plain.grid_of_node)
    assert 0 < new.sum() < 20
    old = graph.node_of_grid[plain.grid_of_node]
    np.testing.assert_array_equal(graph.length_m[old][:, old].toarray(), plain.length_m.toarray())
    _, comp = csg.connected_components(graph.length_m, directed=False)
    assert comp[graph.nearest_node(inside)] == comp[graph.nearest_node(outside)]
    # every node and edge of the bridge keeps the finger's own room, the skin off the true walls
    xy = graph.xyz[new, :2]
    assert np.all(np.abs(xy[:, 0] - 0.5) < 0.013) and np.all((xy[:, 1] > 0.0) & (xy[:, 1] < 0.05))  # in the mouth
    coo = graph.length_m.tocoo()
    on_bridge = new[coo.row] | new[coo.col]
    s = np.linspace(0, 1, 20)[None, :, None]
    pts = graph.xyz[coo.row[on_bridge], None, :2] * (1 - s) + graph.xyz[coo.col[on_bridge], None, :2] * s
    assert _bottle_gap(pts.reshape(-1, 2)).min() >= r_tip + gap - 1e-3
    # a mouth narrower than the finger, or a bridge longer than allowed: still cut off
    for clearance, longest in ((0.014, 0.06), (r_tip + gap, 0.005)):
        g = build_free_graph(_bottle_lattice(), margin, 0.03, -np.inf, None, "distance", clearance, longest)
        assert g.n_nodes == plain.n_nodes


@pytest.mark.parametrize("pocket_link_m, narrow_penalty", [(0.06, 0.0), (0.0, 0.0), (0.0, 3.0)])
def test_the_planner_goes_in_and_out_through_a_narrow_mouth(pocket_link_m, narrow_penalty):
    lat = _bottle_lattice()
    cand = np.array([[0.5, -0.03, Z], [0.5, -0.05, Z]])  # the cavity floor; the block's outer bottom face
    normals = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    params = dict(load_params(str(CONFIG)), strategy="uncertainty", search_quantile=0.0, pocket_link_m=pocket_link_m,
                  narrow_penalty=narrow_penalty)
    m = _as_map(lat, cand[:1], normals[:1])
    res = TouchPlanner.from_params(params, seed=0).plan(m, np.array([0.40, 0.10, Z]))
    if pocket_link_m == 0 and narrow_penalty == 0:
        assert res.status == "all_unreachable" and "in another free-space component" in res.message, res.message
        return
    assert res.ok, res.message
    np.testing.assert_allclose(res.pretouch_xyz, [0.5, -0.01, Z], atol=1e-9)
    s = np.linspace(0, 1, 100)[:, None]

    def skin_gap(path):  # the true clearance of the tip's skin along a path
        pts = np.vstack([a + s * (b - a) for a, b in zip(path[:-1, :2], path[1:, :2])])
        return _bottle_gap(pts).min() - 0.01

    assert skin_gap(res.path_xyz) > 0.0
    # from inside the cavity (after that touch), out through the mouth to the outer bottom face
    m = _as_map(lat, cand[1:], normals[1:])
    out = TouchPlanner.from_params(params, seed=0).plan(m, res.pretouch_xyz)
    assert out.ok, out.message
    np.testing.assert_allclose(out.pretouch_xyz, [0.5, -0.07, Z], atol=1e-9)
    assert skin_gap(out.path_xyz) > 0.0


def test_a_bridge_through_other_cut_off_space_adds_each_edge_once():
    """Two cavities behind one another (a 26 mm mouth, then a 26 mm neck): the inner one's bridge runs
    through the outer cavity's free space, along edges the graph already has; no edge may appear twice
    (the sparse matrix would add their lengths). Oracle: every edge length is a lattice step's length."""
    def sdf(p):
        block = _box_sdf(p, [0.40, -0.09], [0.60, 0.03])
        cavity = np.minimum.reduce([
            _box_sdf(p, [0.46, -0.03], [0.54, 0.01]), _box_sdf(p, [0.487, 0.0], [0.513, 0.2]),  # outer + mouth
            _box_sdf(p, [0.487, -0.045], [0.513, -0.02]), _box_sdf(p, [0.46, -0.085], [0.54, -0.04])])  # neck + inner
        return np.maximum(block, -cavity)

    ax = (np.linspace(0.35, 0.65, 160), np.linspace(-0.15, 0.15, 160))
    X, Y = np.meshgrid(*ax, indexing="ij")
    lat = MapLattice(axes=ax, mean_m=sdf(np.stack([X, Y], axis=-1)), variance_m2=np.full(X.shape, 1e-6), plane_z_m=Z)
    plain = build_free_graph(lat, 0.015, 0.03, -np.inf, None, "distance")
    graph = build_free_graph(lat, 0.015, 0.03, -np.inf, None, "distance", 0.012, 0.1)
    assert csg.connected_components(plain.length_m, directed=False)[0] >= 3
    assert csg.connected_components(graph.length_m, directed=False)[0] == 1
    h = float(np.min(lat.spacing_m))
    steps = [h * np.sqrt(k) for k in (1, 2)]
    lengths = graph.length_m.data
    assert np.all(np.min(np.abs(lengths[:, None] - np.array(steps)[None, :]), axis=1) < 1e-9)


def _channel_lattice(half_width_m, h=0.002, wall_half_m=0.02):
    """Open space split by a wall (|x| ≤ wall_half_m about x = 0.5) pierced by a channel along y = 0. The
    clearance field is written directly: ``half_width_m − |y|`` inside the wall's x range (the distance to
    the channel's walls), 0.1 m elsewhere. Lattice step ``h``, with a row at y = 0."""
    ax = (0.5 + h * np.arange(-40, 41), h * np.arange(-20, 21))
    X, Y = np.meshgrid(*ax, indexing="ij")
    in_wall = np.abs(X - 0.5) <= wall_half_m + 1e-12
    mean = np.where(in_wall, half_width_m - np.abs(Y), 0.1)
    return MapLattice(axes=ax, mean_m=mean, variance_m2=np.full(mean.shape, 1e-6), plane_z_m=Z), in_wall


@pytest.mark.parametrize("penalty", [1.0, 3.0])
def test_a_passage_narrower_than_the_margin_but_not_the_finger_is_a_path_at_its_price(penalty):
    """Oracle: the only way through is the channel's centre row (13 mm of room: < the 15 mm margin, ≥ the
    finger's 12 mm; one row off it has 11 mm). Its cost is the straight length plus (penalty − 1) × the
    edges with an end in the channel: k nodes inside the wall, k + 1 such edges of one step each."""
    h, margin, finger = 0.002, 0.015, 0.012
    lat, in_wall = _channel_lattice(0.013, h)
    a, b = np.array([0.44, 0.0, Z]), np.array([0.56, 0.0, Z])
    walled = build_free_graph(lat, margin, 0.0, -np.inf, None, "mean")  # off: the margin is a wall
    ia, ib = walled.nearest_node(a), walled.nearest_node(b)
    assert not np.isfinite(csg.dijkstra(walled.length_m, indices=ia)[ib])
    graph = build_free_graph(lat, margin, 0.0, -np.inf, None, "mean", finger, 0.0, penalty)
    ia, ib = graph.nearest_node(a), graph.nearest_node(b)
    np.testing.assert_allclose(graph.xyz[[ia, ib]], [a, b], atol=1e-12)
    k = int(in_wall[:, 0].sum())  # channel nodes on the centre row
    cost = csg.dijkstra(graph.length_m, indices=ia)[ib]
    assert cost == pytest.approx(0.12 + (penalty - 1.0) * (k + 1) * h, rel=1e-9)
    # through the channel a segment keeps the finger's room, not the margin (shortcuts keep the margin);
    # the channel's nodes say which they keep, and a node without the finger's room is not in the graph
    seg = np.array([[0.47, 0.0, Z]]), np.array([[0.53, 0.0, Z]])
    assert graph.finger_m == finger and graph.margin_m == margin
    assert graph.segments_free(*seg, clearance_m=finger)[0] and not graph.segments_free(*seg)[0]
    inside, outside = graph.nearest_node(np.array([0.5, 0.0, Z])), ia
    np.testing.assert_allclose(graph.node_clearance_m(np.array([inside, outside])), [finger, margin])
    assert graph.node_of_grid[np.ravel_multi_index((40, 21), lat.shape)] == -1  # (0.5, 0.002): 11 mm
    # a channel too narrow for the finger (11 mm of room) stays shut
    shut = build_free_graph(_channel_lattice(0.011, h)[0], margin, 0.0, -np.inf, None, "mean", finger, 0.0, penalty)
    assert not np.isfinite(csg.dijkstra(shut.length_m, indices=shut.nearest_node(a))[shut.nearest_node(b)])


def test_a_side_wall_of_a_slot_gets_a_pre_touch_point_nearer_the_wall_where_the_finger_has_room():
    """A 26 mm slot: at the full offset (standoff + radius = 20 mm) from its left wall the tip centre is
    6 mm from the right wall; at most 26 − 12 = 14 mm out it keeps the finger's 12 mm from both. Oracle: the
    slot's walls (x = 0.5 ± half width), not the planner's clearance."""
    finger, full = 0.012, 0.02
    graph = build_free_graph(_lattice(0.013), 0.015, 0.03, -np.inf, None, "distance")
    h4 = float(np.min(graph.lattice.spacing_m)) / 4.0
    wall = np.array([[0.5 - 0.013, 0.02, Z]])
    n = np.array([[1.0, 0.0, 0.0]])
    pre = closer_pretouch(graph, wall, n, full, 0.012, finger)
    d = pre[0, 0] - wall[0, 0]
    np.testing.assert_allclose(pre[0, 1:], wall[0, 1:])  # along the normal
    assert 0.014 - h4 - 1e-3 <= d <= 0.014 + 1e-3  # the largest sampled offset with room (lattice tolerance)
    # 22 mm: no offset between 12 and 20 mm leaves 12 mm to the other wall: the full one stays
    narrow = build_free_graph(_lattice(0.011), 0.015, 0.03, -np.inf, None, "distance")
    np.testing.assert_allclose(closer_pretouch(narrow, wall + [[0.002, 0, 0]], n, full, 0.012, finger),
                               wall + [[0.002 + full, 0, 0]])
    # a wall with room at the full offset keeps it
    free_side = np.array([[0.56, 0.0, Z]])
    np.testing.assert_allclose(closer_pretouch(graph, free_side, n, full, 0.012, finger), free_side + [[full, 0, 0]])
