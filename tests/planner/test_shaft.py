"""The finger's shaft: no path, approach or slide puts the vertical rod into the estimated object.

The estimate here is an exact signed distance (independent of the planner): a mushroom, a 12 × 12 cm
deck 2 cm thick at 10–12 cm over a 3 × 3 cm pillar standing on the table.
"""

import numpy as np
import pytest

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE
from tactile_planner.graph import build_free_graph, shaft_column_min
from tactile_planner.maps import MapLattice
from tactile_planner.planner import TouchPlanner
from tactile_planner.slides import trace
from tactile_planner.synthetic import WORKSPACE_3D

CENTRE = np.array([0.5, 0.0])
SHAFT = {"shaft_clear": True, "shaft_length_m": 0.16, "shaft_radius_m": 0.005, "shaft_gap_m": 0.002}


def box_sdf(p: np.ndarray, lo, hi) -> np.ndarray:
    """Exact signed distance to the axis-aligned box [lo, hi] at (N, 3) points."""
    c, h = (np.asarray(lo) + np.asarray(hi)) / 2, (np.asarray(hi) - np.asarray(lo)) / 2
    q = np.abs(p - c) - h
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def mushroom_sdf(p: np.ndarray) -> np.ndarray:
    deck = box_sdf(p, (0.44, -0.06, 0.10), (0.56, 0.06, 0.12))
    pillar = box_sdf(p, (0.485, -0.015, 0.0), (0.515, 0.015, 0.10))
    return np.minimum(deck, pillar)


def mushroom_lattice(n: int = 48) -> MapLattice:
    axes = tuple(np.linspace(lo, hi, n) for lo, hi in WORKSPACE_3D)
    pts = np.stack([m.ravel() for m in np.meshgrid(*axes, indexing="ij")], axis=1)
    mu = mushroom_sdf(pts).reshape((n,) * 3)
    return MapLattice(axes, mu, np.full(mu.shape, 1e-4), None)


def mushroom_map(candidates_xyz: np.ndarray, normals_xyz: np.ndarray, n: int = 48) -> np.ndarray:
    lat = mushroom_lattice(n)
    pts = lat.grid_xyz()
    rows = np.zeros(len(pts), VARIANCE_MAP_DTYPE)
    rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    rows["mean"], rows["variance"], rows["kind"] = lat.mean_m.ravel(), 1e-4, KIND_LATTICE
    cand = np.zeros(len(candidates_xyz), VARIANCE_MAP_DTYPE)
    cand["x"], cand["y"], cand["z"] = np.asarray(candidates_xyz, float).T
    cand["normal_x"], cand["normal_y"], cand["normal_z"] = np.asarray(normals_xyz, float).T
    cand["variance"], cand["kind"] = 1e-4, KIND_CANDIDATE
    return np.concatenate([rows, cand])


@pytest.mark.parametrize("length_m", [0.005, 0.012, 0.035, 0.08, 0.11, 0.5])
def test_the_column_minimum_is_the_minimum_over_the_nodes_above(length_m):
    rng = np.random.default_rng(0)
    field = rng.normal(size=(4, 5, 20))
    z = np.linspace(0.0, 0.19, 20)  # 10 mm apart: 0.035 m reaches 3 nodes up
    K = int(np.floor(length_m / 0.01 + 1e-9))
    got = shaft_column_min(field, z, length_m)
    want = np.full(field.shape, np.inf)
    for k in range(20):
        above = field[:, :, k + 1: k + 1 + K]
        if above.shape[2]:
            want[:, :, k] = above.min(axis=2)
    np.testing.assert_array_equal(got, want)


def test_no_free_node_lies_under_the_deck_and_every_other_node_keeps_its_freedom():
    lat = mushroom_lattice()
    margin, need, length = 0.015, 0.010, 0.15
    plain = build_free_graph(lat, margin, shell_m=0.03, min_z_m=0.015)
    shaft = build_free_graph(lat, margin, shell_m=0.03, min_z_m=0.015, shaft_length_m=length,
                             shaft_clearance_m=need)
    # brute force: a node keeps its freedom iff every lattice node above it within the rod's length clears
    mu, dz = lat.mean_m, float(lat.axes[2][1] - lat.axes[2][0])
    K = int(np.floor(length / dz + 1e-9))
    clear = np.ones(mu.shape, bool)
    for k in range(mu.shape[2]):
        above = mu[:, :, k + 1: k + 1 + K]
        if above.shape[2]:
            clear[:, :, k] = above.min(axis=2) >= need
    np.testing.assert_array_equal(shaft.free, plain.free & clear)
    under = np.array([0.54, 0.0, 0.05])  # 2.5 cm beside the pillar, 5 cm under the deck
    beside = np.array([0.58, 0.0, 0.09])  # outside the deck's footprint, 2 cm from its edge
    idx = lambda p: tuple(int(np.argmin(np.abs(a - v))) for a, v in zip(lat.axes, p))  # noqa: E731
    assert plain.free[idx(under)] and not shaft.free[idx(under)]
    assert plain.free[idx(beside)] and shaft.free[idx(beside)]
    # shortcuts test the same clearance: a straight segment under the deck is not free, one beside it is
    assert not shaft.segments_free(under[None] + [0, -0.03, 0], under[None] + [0, 0.03, 0])[0]
    assert shaft.segments_free(beside[None] + [0, -0.03, 0], beside[None] + [0, 0.03, 0])[0]


@pytest.mark.parametrize("euclidean", [False, True])
def test_a_segment_is_free_whatever_else_is_asked_with_it(euclidean):
    """Straight segments 1 mm to 20 cm long round the mushroom: free iff the exact distance along them
    (densely sampled) keeps the margin, wherever that is clear by more than the lattice's error; and each
    answer is the same asked alone or beside a long segment (each is sampled at its own step)."""
    lat = mushroom_lattice()
    graph = build_free_graph(lat, 0.015, shell_m=0.03, min_z_m=0.015)
    rng = np.random.default_rng(5)
    a = rng.uniform([0.40, -0.10, 0.02], [0.60, 0.10, 0.16], size=(300, 3))
    d = rng.normal(size=(300, 3))
    b = a + d / np.linalg.norm(d, axis=1, keepdims=True) * np.geomspace(0.001, 0.2, 300)[:, None]
    t = np.linspace(0.0, 1.0, 2001)
    exact_min = np.array([mushroom_sdf(p + t[:, None] * (q - p)).min() for p, q in zip(a, b)])
    got = graph.segments_free(a, b, euclidean=euclidean)
    inside = np.all([(np.minimum(a[:, k], b[:, k]) > lo) & (np.maximum(a[:, k], b[:, k]) < hi)
                     for k, (lo, hi) in enumerate(zip([0.35, -0.15, 0.016], [0.65, 0.15, 0.22]))], axis=0)
    clear = (np.abs(exact_min - 0.015) > 0.004) & inside  # not under the tip's lowest height, in the lattice
    assert clear.sum() > 200 and 20 < (exact_min[clear] >= 0.015).sum() < clear.sum() - 20
    np.testing.assert_array_equal(got[clear], exact_min[clear] >= 0.015)
    alone = np.array([graph.segments_free(p[None], q[None], euclidean=euclidean)[0] for p, q in zip(a, b)])
    np.testing.assert_array_equal(got, alone)
    assert graph.segments_free(a[:0], b[:0]).shape == (0,)


def test_approaches_that_would_put_the_rod_into_the_deck_are_excluded_and_others_are_not():
    cands = np.array([
        [0.515, 0.0, 0.05],  # the pillar's side, under the deck
        [0.56, 0.0, 0.11],   # the deck's outer side wall
        [0.50, 0.03, 0.12],  # the deck's top
        [0.50, 0.06, 0.11],  # the deck's other side wall
    ])
    normals = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])
    m = mushroom_map(cands, normals)
    tip = np.array([0.62, 0.0, 0.16])
    params = {"mode": "3d", "strategy": "uncertainty", "support_gap_m": 0.0, **SHAFT}
    planner = TouchPlanner.from_params(params, seed=0)
    res = planner.plan(m, tip)
    assert res.ok
    blocked = planner.last_why["the finger's shaft would enter the estimate"]
    assert blocked.tolist() == [True, False, False, False]
    # without the shaft the pillar's side under the deck is a candidate like the others
    off = TouchPlanner.from_params({**params, "shaft_clear": False}, seed=0)
    off.plan(m, tip)
    assert "the finger's shaft would enter the estimate" not in off.last_why
    # every path the planner sends keeps the rod out of the estimate: its tip never passes under the deck
    for k in range(3):
        path = planner.plan(m, tip).path_xyz
        seg = np.vstack([a + np.linspace(0, 1, 20)[:, None] * (b - a) for a, b in zip(path[:-1], path[1:])])
        under = (np.abs(seg[:, 0] - 0.5) < 0.06 + 0.005) & (np.abs(seg[:, 1]) < 0.06 + 0.005) & (seg[:, 2] < 0.10)
        assert not under.any(), k


def test_a_slide_down_the_deck_side_goes_straight_down_past_its_edge_instead_of_under_it():
    """Down the deck's outer wall: where the surface turns under the deck the rod would enter it, so the
    trace goes on straight down beside the deck (tactile_planner.slides: the finger follows a wall
    down; on this mushroom the servo's contact ends at the edge) and never under it."""
    lat = mushroom_lattice(64)
    start = np.array([[0.56, 0.0, 0.11]])  # the deck's outer side wall, sliding down it
    down = np.array([[0.0, 0.0, -1.0]])
    pts, _, ok = trace(lat, start, down, 0.003, 20)
    valid = np.cumprod(ok[0]).astype(bool)
    # without the rod the trace turns round the deck's lower edge onto its underside
    assert np.any((pts[0, valid, 2] < 0.1005) & (pts[0, valid, 0] < 0.55))
    graph = build_free_graph(lat, 0.015, shell_m=0.03, min_z_m=0.015, shaft_length_m=0.15,
                             shaft_clearance_m=0.010)
    rod_clear = lambda x, n: graph.rod_clearance_m(x + 0.01 * n, 0.01) >= 0.007  # noqa: E731
    pts, _, ok = trace(lat, start, down, 0.003, 20, surface_ok=rod_clear)
    p = pts[0, np.cumprod(ok[0]).astype(bool)]
    assert len(p) == 21 and p[-1, 2] < 0.06  # all the way down
    assert (p[:, 0] > 0.555).all()  # beside the deck, never under it
    edge = next(i for i in range(len(p)) if np.all(p[i:, :2] == p[i, :2]))  # from here straight down
    assert 0.095 < p[edge, 2] < 0.105  # the deck's lower edge (z = 0.10)


@pytest.mark.parametrize("d", [0.004, 0.011, 0.023])
def test_the_rod_beside_the_deck_clears_it_by_its_distance_and_under_it_not_at_all(d):
    """The rod above a tip below the deck's level, d out from its side face: the clearance is d
    (the exact sdf of the face is linear, so the lattice's multilinear interpolation keeps it)."""
    graph = build_free_graph(mushroom_lattice(), 0.015, shell_m=0.03, min_z_m=0.015, shaft_length_m=0.16,
                             shaft_clearance_m=0.010)
    tip = np.array([[0.56 + d, 0.0, 0.05]])
    assert graph.rod_clearance_m(tip, 0.01)[0] == pytest.approx(d, abs=2e-4)
    assert graph.rod_clearance_m(tip - [0.04, 0, 0], 0.01)[0] < -0.005  # under the deck: the rod is in it
    off = build_free_graph(mushroom_lattice(), 0.015, shell_m=0.03, min_z_m=0.015)
    assert np.isinf(off.rod_clearance_m(tip, 0.01)).all()  # no rod modelled


def test_no_candidate_left_for_the_rod_check_is_a_plain_all_unreachable():
    m = mushroom_map(np.array([[0.56, 0.0, 0.11]]), np.array([[1.0, 0, 0]]))
    planner = TouchPlanner.from_params({"mode": "3d", "min_normal_z": 1.0, "search_quantile": 0.0,
                                        "support_gap_m": 0.0, **SHAFT}, seed=0)  # every normal "faces down"
    res = planner.plan(m, np.array([0.62, 0.0, 0.16]))
    assert res.status == "all_unreachable" and "facing down" in res.message
    assert not planner.last_why["the finger's shaft would enter the estimate"].any()


def _passes_under_the_deck(path_xyz: np.ndarray) -> bool:
    seg = np.vstack([a + np.linspace(0, 1, 20)[:, None] * (b - a) for a, b in zip(path_xyz[:-1], path_xyz[1:])])
    return bool(np.any((np.abs(seg[:, 0] - 0.5) < 0.065) & (np.abs(seg[:, 1]) < 0.065) & (seg[:, 2] < 0.10)))


def test_a_path_to_the_far_side_goes_over_the_deck_not_under_it():
    """From low beside the deck to its far side wall the shortest tip path runs under the deck (the rod
    through it); with the rod considered the path climbs over it."""
    m = mushroom_map(np.array([[0.44, 0.0, 0.11]]), np.array([[-1.0, 0, 0]]))
    tip = np.array([0.58, 0.0, 0.04])
    params = {"mode": "3d", "strategy": "uncertainty", "support_gap_m": 0.0, **SHAFT}
    tip_only = TouchPlanner.from_params({**params, "shaft_clear": False}, seed=0).plan(m, tip)
    with_rod = TouchPlanner.from_params(params, seed=0).plan(m, tip)
    assert tip_only.ok and _passes_under_the_deck(tip_only.path_xyz)  # what the rod check prevents
    assert with_rod.ok and not _passes_under_the_deck(with_rod.path_xyz)
    assert with_rod.path_length_m > tip_only.path_length_m
