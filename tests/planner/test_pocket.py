"""A candidate at the bottom of a slot the estimate shows too narrow for the path margin but wide enough
for the finger (tactile_planner.pocket): entered along its approach axis instead of being unreachable.
Oracle: the slot's signed distance, computed here from its boxes (not from the planner's clearance)."""

from pathlib import Path

import numpy as np
import pytest

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE
from tactile_planner.graph import build_free_graph
from tactile_planner.maps import MapLattice
from tactile_planner.planner import TouchPlanner, load_params
from tactile_planner.pocket import pocket_entries

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


@pytest.mark.parametrize("pocket_entry_m", [0.03, 0.0])
def test_the_planner_touches_the_slot_bottom_through_its_entry(pocket_entry_m):
    lat = _lattice(0.013)
    cand = np.array([[0.5, 0.0, Z]])
    m = _as_map(lat, cand, np.array([[0.0, 1.0, 0.0]]))
    params = dict(load_params(str(CONFIG)), strategy="uncertainty", search_quantile=0.0, pocket_entry_m=pocket_entry_m)
    res = TouchPlanner.from_params(params, seed=0).plan(m, np.array([0.40, 0.10, Z]))
    if pocket_entry_m == 0:
        assert res.status == "all_unreachable" and "no free pre-touch point" in res.message, res.message
        return
    assert res.ok, res.message
    np.testing.assert_allclose(res.pretouch_xyz, [0.5, 0.02, Z], atol=1e-9)
    np.testing.assert_allclose(res.path_xyz[-1], res.pretouch_xyz)
    last = res.path_xyz[-2]  # the entry: straight above, on the approach axis
    assert abs(last[0] - 0.5) < 1e-9 and last[1] > 0.02
    # the whole path keeps the finger off the slot's true walls (skin gap > 0), the graph part the margin
    s = np.linspace(0, 1, 100)[:, None]
    pts = np.vstack([a + s * (b - a) for a, b in zip(res.path_xyz[:-1, :2], res.path_xyz[1:, :2])])
    assert _slot_sdf(pts, 0.013).min() > 0.01
