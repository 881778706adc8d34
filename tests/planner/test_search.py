"""Search for a lost object (tactile_planner.search): when every touch missed, the planner probes
where the object is most probable instead of stopping. Oracles: P(inside) = Φ(−μ/σ) computed
here with scipy.stats, and finite differences of it along the candidates' normals."""

from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from tactile_common.fields import KIND_LATTICE, VARIANCE_MAP_DTYPE
from tactile_planner.maps import MapLattice, parse_variance_map
from tactile_planner.planner import TouchPlanner, load_params
from tactile_planner.search import floating_base, ring_radii_m, ring_search_map, search_field, search_map

CONFIG = Path(__file__).resolve().parents[2] / "src/tactile_planner/config/soc_planner.yaml"


def _lost_lattice(n: int = 64) -> MapLattice:
    """A 2D lattice whose mean is > 0 everywhere (misses lifted it), least so, and most uncertain,
    around (0.55, 0.05): where the object most probably is."""
    ax = (np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n))
    X, Y = np.meshgrid(*ax, indexing="ij")
    d = np.hypot(X - 0.55, Y - 0.05)
    mean = 0.01 + 0.2 * d
    var = (0.02 + 0.1 * np.exp(-(d / 0.05) ** 2)) ** 2
    return MapLattice(axes=ax, mean_m=mean, variance_m2=var, plane_z_m=0.06)


def _as_map(lattice: MapLattice) -> np.ndarray:
    X, Y = np.meshgrid(*lattice.axes, indexing="ij")
    out = np.zeros(X.size, dtype=VARIANCE_MAP_DTYPE)
    out["x"], out["y"], out["z"] = X.ravel(), Y.ravel(), lattice.plane_z_m
    out["mean"], out["variance"] = lattice.mean_m.ravel(), lattice.variance_m2.ravel()
    out["kind"] = KIND_LATTICE
    return out


@pytest.mark.parametrize("q", [0.05, 0.1, 0.3])
def test_search_field_is_negative_on_the_most_probable_fraction(q):
    lat = _lost_lattice()
    s = search_field(lat, q)
    p_inside = norm.cdf(-lat.mean_m / np.sqrt(lat.variance_m2))
    inside = s < 0
    assert abs(inside.mean() - q) <= 2.0 / inside.size
    # every node of the search region is at least as probable as every node outside it
    assert p_inside[inside].min() >= p_inside[~inside].max() - 1e-12


def test_search_candidates_lie_on_the_search_surface_facing_less_probable_space():
    lat = _lost_lattice()
    found = search_map(lat, 0.1, max_candidates=50)
    assert found is not None
    search_lat, cands = found
    assert 0 < len(cands) <= 50
    from scipy.interpolate import RegularGridInterpolator

    s_at = RegularGridInterpolator(lat.axes, search_lat.mean_m)(cands.xyz[:, :2])
    assert np.abs(s_at).max() < 1e-3  # on the zero level set (linear interpolation on the lattice)
    # the outward normal points to where the object is less probable (finite differences of P(inside))
    p_in = RegularGridInterpolator(lat.axes, norm.cdf(-lat.mean_m / np.sqrt(lat.variance_m2)))
    eps = 2e-3
    ahead = p_in(cands.xyz[:, :2] + eps * cands.normal[:, :2])
    behind = p_in(cands.xyz[:, :2] - eps * cands.normal[:, :2])
    assert np.all(ahead < behind)
    np.testing.assert_allclose(np.linalg.norm(cands.normal, axis=1), 1.0)
    assert np.all(cands.xyz[:, 2] == 0.06) and np.all(cands.normal[:, 2] == 0.0)
    # the candidates surround the most probable spot
    assert np.linalg.norm(cands.xyz[:, :2].mean(axis=0) - [0.55, 0.05]) < 0.01


def test_the_planner_searches_instead_of_stopping_and_says_so():
    # the probability search alone (the coverage rings come first when nothing was touched: below)
    params = dict(load_params(str(CONFIG)), strategy="info_travel", search_ring_spacing_m=0.0)
    tip = np.array([0.38, -0.12, 0.06])
    res = TouchPlanner.from_params(params, seed=1).plan(_as_map(_lost_lattice()), tip)
    assert res.ok and res.message.startswith("search"), res.message
    # on the boundary of the search region: a disc around the most probable spot holding 10 % of the area
    radius = np.sqrt(0.1 * 0.3 * 0.3 / np.pi)
    assert abs(np.linalg.norm(res.target_xyz[:2] - [0.55, 0.05]) - radius) < 0.01
    # the approach goes into the most probable region
    assert np.dot(-res.normal_xyz[:2], np.array([0.55, 0.05]) - res.target_xyz[:2]) > 0
    off = TouchPlanner.from_params(dict(params, search_quantile=0.0), seed=1).plan(_as_map(_lost_lattice()), tip)
    assert off.status == "no_candidates"


def test_a_search_never_probes_the_same_spot_twice():
    params = dict(load_params(str(CONFIG)), strategy="info_travel")
    planner = TouchPlanner.from_params(params, seed=1)
    tip = np.array([0.38, -0.12, 0.06])
    m = _as_map(_lost_lattice())
    targets = []
    for _ in range(6):  # the same map (the misses taught nothing): the search still moves on
        res = planner.plan(m, tip)
        if not res.ok:
            break
        targets.append(res.target_xyz)
    assert len(targets) >= 3
    d = np.linalg.norm(np.array(targets)[:, None, :2] - np.array(targets)[None, :, :2], axis=2)
    assert d[np.triu_indices(len(targets), 1)].min() > params["revisit_radius_m"]
    assert parse_variance_map(m)[1].xyz.shape[0] == 0  # the map itself never had candidates


# -- coverage rings: when the probability search has nothing left (or nothing was ever touched) ------

def test_ring_radii_start_at_the_workspace_scale_alternate_and_leave_no_gap_wider_than_a_probe():
    lat = _lost_lattice()
    step = 0.04
    radii = np.array(ring_radii_m(lat, step))
    assert radii[0] == pytest.approx(0.25 * 0.3)  # a quarter of the smallest horizontal extent
    assert np.all(np.diff(np.abs(radii - radii[0])) >= -1e-12)  # nearest to the first ring first
    X, Y = np.meshgrid(*lat.axes, indexing="ij")
    d = np.hypot(X - 0.5, Y - 0.0).ravel()  # the lattice's centre, computed here
    covered = np.abs(d[:, None] - radii[None, :]).min(axis=1)
    assert covered[d >= 0.5 * step].max() <= 0.5 * step + 1e-9  # every node within half a step of a ring
    assert radii.min() >= 0.5 * step and radii.max() <= np.hypot(0.15, 0.15) + 1e-9


@pytest.mark.parametrize("dim", [2, 3])
def test_ring_candidates_lie_on_the_ring_face_outwards_and_stay_on_the_lattice(dim):
    if dim == 2:
        lat = _lost_lattice()
        centre = np.array([0.5, 0.0])
    else:
        ax = (np.linspace(0.35, 0.65, 24), np.linspace(-0.15, 0.15, 24), np.linspace(0.0, 0.22, 18))
        grids = np.meshgrid(*ax, indexing="ij")
        lat = MapLattice(axes=ax, mean_m=0.05 + 0 * grids[0], variance_m2=1e-3 + 0 * grids[0], plane_z_m=0.0)
        centre = np.array([0.5, 0.0, 0.0])  # on the table, under the workspace's middle
    radius, spacing, inset = 0.115, 0.02, 0.02
    search_lat, c = ring_search_map(lat, radius, spacing, min_z_m=0.015, inset_m=inset)
    p = c.xyz[:, :dim]
    np.testing.assert_allclose(np.linalg.norm(p - centre, axis=1), radius, atol=1e-12)
    np.testing.assert_allclose(c.normal[:, :dim], (p - centre) / radius, atol=1e-12)
    lo = np.array([a[0] for a in lat.axes]) + inset
    hi = np.array([a[-1] for a in lat.axes]) - inset
    assert np.all((p >= lo - 1e-12) & (p <= hi + 1e-12))
    if dim == 3:
        assert p[:, 2].min() >= 0.015
    # about `spacing` apart: every candidate has a neighbour within 1.6 spacings, none closer than half
    d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(len(p))
    assert d.min() > 0.5 * spacing and d.min(axis=1).max() < 1.6 * spacing
    from scipy.interpolate import RegularGridInterpolator
    s_at = RegularGridInterpolator(lat.axes, search_lat.mean_m)(p)
    assert np.abs(s_at).max() < 2e-3  # the planning field's zero level set is the ring (lattice interpolation)


def test_3d_table_rings_sweep_the_annulus_at_the_lowest_probe_height():
    """``table_z_m``: the 3D ring is the horizontal circle at that height, approached level towards the
    centre. Oracle: the probes' swept volumes (the tip's ball from the pre-touch point to the approach's
    end, the config's geometry) cover every point of the annulus 2 cm wide inside the ring at that height:
    an object on the table whose footprint reaches into it is met, however flat."""
    ax = (np.linspace(0.35, 0.65, 24), np.linspace(-0.15, 0.15, 24), np.linspace(0.0, 0.22, 18))
    grids = np.meshgrid(*ax, indexing="ij")
    lat = MapLattice(axes=ax, mean_m=0.05 + 0 * grids[0], variance_m2=1e-3 + 0 * grids[0], plane_z_m=0.0)
    radius, spacing, z = 0.075, 0.02, 0.017
    search_lat, c = ring_search_map(lat, radius, spacing, min_z_m=0.015, inset_m=0.02, table_z_m=z)
    assert len(c) == int(np.ceil(2 * np.pi * radius / spacing))  # a hemisphere would need ~88
    np.testing.assert_allclose(c.xyz[:, 2], z)
    np.testing.assert_allclose(c.normal[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(c.xyz[:, 0] - 0.5, c.xyz[:, 1]), radius, atol=1e-12)
    np.testing.assert_allclose(c.normal[:, :2], (c.xyz[:, :2] - [0.5, 0.0]) / radius, atol=1e-12)
    # the planning field is the vertical cylinder through the circle (paths keep off it at any height)
    X, Y, _ = grids
    np.testing.assert_allclose(search_lat.mean_m, np.hypot(X - 0.5, Y) - radius, atol=1e-12)
    p = load_params(str(CONFIG))
    r, pre_m, depth = p["tip_radius_m"], p["tip_radius_m"] + p["standoff_m"], p["max_depth_m"]
    a = c.xyz + pre_m * c.normal  # pre-touch tip centres
    b = c.xyz + (r - depth) * c.normal  # the approach's end
    rho, phi = np.meshgrid(np.linspace(radius - 0.02, radius, 21), np.linspace(0, 2 * np.pi, 721))
    q = np.column_stack([0.5 + rho.ravel() * np.cos(phi.ravel()), rho.ravel() * np.sin(phi.ravel()),
                         np.full(rho.size, z)])
    t = np.clip(np.einsum("qkd,kd->qk", q[:, None] - a[None], b - a) / np.sum((b - a) ** 2, axis=1), 0, 1)
    dist = np.linalg.norm(q[:, None] - (a[None] + t[..., None] * (b - a)[None]), axis=2).min(axis=1)
    assert dist.max() <= r + 1e-9


def test_3d_table_ring_field_is_the_distance_to_a_cylinder_capped_above_the_ring():
    """``cap_above_m``: the planning field is the signed distance to the solid cylinder from the
    table up to that height above the ring. Oracle: the distance to points sampled on its side wall
    and top (≤ 1 mm apart), negative inside."""
    ax = (np.linspace(0.35, 0.65, 16), np.linspace(-0.15, 0.15, 16), np.linspace(0.0, 0.22, 12))
    grids = np.meshgrid(*ax, indexing="ij")
    lat = MapLattice(axes=ax, mean_m=0.05 + 0 * grids[0], variance_m2=1e-3 + 0 * grids[0], plane_z_m=0.0)
    radius, z, cap = 0.075, 0.017, 0.02
    search_lat, _ = ring_search_map(lat, radius, 0.02, min_z_m=0.015, inset_m=0.02, table_z_m=z, cap_above_m=cap)
    top = z + cap
    phi = np.linspace(0, 2 * np.pi, 500, endpoint=False)
    wall = [np.column_stack([0.5 + radius * np.cos(phi), radius * np.sin(phi), np.full(phi.size, h)])
            for h in np.arange(-0.3, top, 0.001)]  # the wall goes on below the lattice (the table)
    disc = [np.column_stack([0.5 + r * np.cos(phi), r * np.sin(phi), np.full(phi.size, top)])
            for r in np.arange(0.0, radius + 1e-9, 0.001)]
    surface = np.vstack(wall + disc)
    from scipy.spatial import cKDTree
    q = np.column_stack([g.ravel() for g in grids])
    d = cKDTree(surface).query(q)[0]
    inside = (np.hypot(q[:, 0] - 0.5, q[:, 1]) < radius) & (q[:, 2] < top)
    np.testing.assert_allclose(search_lat.mean_m.ravel(), np.where(inside, -d, d), atol=1e-3)


def test_a_tip_left_inside_the_table_ring_leaves_it_over_the_top():
    """A probe that missed leaves the tip inside the ring at the probe height: the next ring probe's
    path goes over the ring's cap (a pre-touch offset above it), not up to the lattice's top as round
    an endless cylinder."""
    params = dict(load_params(str(CONFIG)), mode="3d", strategy="info_travel", clearance="mean",
                  search_rings_first=True, search_rings_3d="table")
    ax = (np.linspace(0.35, 0.65, 31), np.linspace(-0.15, 0.15, 31), np.linspace(0.0, 0.22, 23))
    grids = np.meshgrid(*ax, indexing="ij")
    lat = MapLattice(axes=ax, mean_m=0.05 + 0 * grids[0], variance_m2=1e-3 + 0 * grids[0], plane_z_m=None)
    X, Y, Z = grids
    m = np.zeros(X.size, dtype=VARIANCE_MAP_DTYPE)
    m["x"], m["y"], m["z"] = X.ravel(), Y.ravel(), Z.ravel()
    m["mean"], m["variance"], m["kind"] = lat.mean_m.ravel(), lat.variance_m2.ravel(), KIND_LATTICE
    tip = np.array([0.5, 0.01, 0.03])  # in the ring, below its top
    res = TouchPlanner.from_params(params, seed=1).plan(m, tip)
    assert res.ok and "coverage ring" in res.message, res.message
    pretouch_m = params["tip_radius_m"] + params["standoff_m"]
    top = res.target_xyz[2] + pretouch_m  # the cap: a pre-touch offset above the ring
    path = res.path_xyz
    np.testing.assert_allclose(path[-1], res.pretouch_xyz, atol=1e-9)
    assert path[:, 2].max() <= top + params["margin_m"] + 0.011, path  # + one lattice spacing
    # straight up out of it, then over the cap: never through the ring's wall below its top
    t = np.linspace(0.0, 1.0, 50)[:, None, None]
    q = (path[:-1][None] + t * np.diff(path, axis=0)[None]).reshape(-1, 3)
    ring_r = np.hypot(res.target_xyz[0] - 0.5, res.target_xyz[1])
    column = np.hypot(q[:, 0] - tip[0], q[:, 1] - tip[1]) < 1e-9
    assert np.all(column | (q[:, 2] >= top) | (np.hypot(q[:, 0] - 0.5, q[:, 1]) >= ring_r - 1e-3)), path


def test_a_lost_object_is_searched_where_most_probable_then_ring_by_ring_each_spot_once():
    """No estimated surface: the planner probes where the object is most probable; once every spot
    there was probed (the same map every time: the misses taught nothing), it covers the workspace
    with rings, nearest first, and never probes a spot twice; with the rings off it ends there."""
    params = dict(load_params(str(CONFIG)), strategy="info_travel")
    planner = TouchPlanner.from_params(params, seed=1)
    tip = np.array([0.38, -0.12, 0.06])
    m = _as_map(_lost_lattice())
    radii = ring_radii_m(_lost_lattice(), 0.01 + 0.03)  # standoff + max depth (config defaults)
    targets, kinds, rings = [], [], []
    for _ in range(200):
        res = planner.plan(m, tip)
        if not res.ok:  # every ring used up: the workspace is covered
            break
        targets.append(res.target_xyz[:2])
        kinds.append("ring" if "coverage ring" in res.message else "probable")
        if kinds[-1] == "ring":
            rings.append(float(res.message.split("r = ")[1].split(" m")[0]))
    assert kinds[0] == "probable" and "ring" in kinds
    first_ring = kinds.index("ring")
    assert set(kinds[first_ring:]) == {"ring"}  # the probable region was used up first
    t = np.array(targets)
    d = np.linalg.norm(t[:, None] - t[None], axis=2)
    assert d[np.triu_indices(len(t), 1)].min() > params["revisit_radius_m"]
    assert rings[0] == pytest.approx(radii[0], abs=1e-3)
    order = [radii.index(min(radii, key=lambda r: abs(r - x))) for x in rings]
    assert order == sorted(order) and len(set(order)) >= 3  # ring after ring, each one exhausted
    assert not res.ok and res.status == "all_unreachable"  # it ends only once the rings are used up
    np.testing.assert_allclose(np.linalg.norm(t[first_ring:] - [0.5, 0.0], axis=1), rings, atol=1e-9)
    off = TouchPlanner.from_params(dict(params, search_ring_spacing_m=0.0), seed=1)
    for _ in range(first_ring):
        off.plan(m, tip)
    assert not off.plan(m, tip).ok  # without the rings the search ends where the probable region does


def _prior_lattice(n: int = 64) -> MapLattice:
    """A 2D lattice that still holds the prior: a disc of radius 0.075 m at the workspace centre."""
    ax = (np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n))
    X, Y = np.meshgrid(*ax, indexing="ij")
    d = np.hypot(X - 0.5, Y)
    return MapLattice(axes=ax, mean_m=d - 0.075, variance_m2=np.full(X.shape, 0.01), plane_z_m=0.06)


def _with_candidates(lattice: MapLattice, k: int = 24) -> np.ndarray:
    """The map of ``lattice`` plus k candidates on the disc's circle (outward normals)."""
    from tactile_common.fields import KIND_CANDIDATE

    a = np.linspace(0.0, 2 * np.pi, k, endpoint=False)
    c = np.zeros(k, dtype=VARIANCE_MAP_DTYPE)
    c["x"], c["y"], c["z"] = 0.5 + 0.075 * np.cos(a), 0.075 * np.sin(a), 0.06
    c["normal_x"], c["normal_y"] = np.cos(a), np.sin(a)
    c["variance"], c["kind"] = 0.01, KIND_CANDIDATE
    return np.concatenate([_as_map(lattice), c])


@pytest.mark.parametrize("after, misses, ring", [(3, 3, True), (3, 5, True), (3, 2, False), (0, 9, False)])
def test_misses_before_any_contact_start_the_coverage_rings_on_a_prior_with_a_surface(after, misses, ring):
    """search_after_misses: a prior that touches keep refuting is not searched along (its surface
    is a guess): from the k-th miss with no contact yet the planner covers the workspace with rings."""
    params = dict(load_params(str(CONFIG)), strategy="info_travel", search_after_misses=after)
    m = _with_candidates(_prior_lattice())
    assert len(parse_variance_map(m)[1]) == 24
    res = TouchPlanner.from_params(params, seed=1).plan(m, np.array([0.38, -0.12, 0.06]),
                                                        misses_before_contact=misses)
    assert res.ok, res.message
    assert ("coverage ring" in res.message) is ring, res.message
    if ring:
        assert f"{misses} touches met nothing" in res.message
    else:  # one of the disc's candidates
        assert abs(np.hypot(res.target_xyz[0] - 0.5, res.target_xyz[1]) - 0.075) < 1e-6


# -- an estimate that floats above the table: search under it --------------------------------------

def _blob_lattice(z_centre: float, radius: float = 0.03, n: int = 31) -> MapLattice:
    """A 3D lattice whose estimate is a ball of ``radius`` at (0.5, 0.0, z_centre) (μ = distance − r)."""
    ax = (np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n), np.linspace(0.0, 0.22, 23))
    X, Y, Z = np.meshgrid(*ax, indexing="ij")
    d = np.sqrt((X - 0.5) ** 2 + Y ** 2 + (Z - z_centre) ** 2)
    return MapLattice(axes=ax, mean_m=d - radius, variance_m2=np.full(X.shape, 1e-4), plane_z_m=None)


def _map3d(lattice: MapLattice, k: int = 60) -> np.ndarray:
    """The 3D map of ``lattice`` plus k candidates on the upper half of its ball."""
    from tactile_common.fields import KIND_CANDIDATE

    X, Y, Z = np.meshgrid(*lattice.axes, indexing="ij")
    out = np.zeros(X.size, dtype=VARIANCE_MAP_DTYPE)
    out["x"], out["y"], out["z"] = X.ravel(), Y.ravel(), Z.ravel()
    out["mean"], out["variance"], out["kind"] = lattice.mean_m.ravel(), lattice.variance_m2.ravel(), KIND_LATTICE
    i = np.argmin(lattice.mean_m.reshape(-1))
    c = np.array([X.ravel()[i], Y.ravel()[i], Z.ravel()[i]])
    r = -float(lattice.mean_m.reshape(-1)[i])
    g = np.random.default_rng(0).normal(size=(k, 3))
    g[:, 2] = np.abs(g[:, 2])
    n = g / np.linalg.norm(g, axis=1, keepdims=True)
    cand = np.zeros(k, dtype=VARIANCE_MAP_DTYPE)
    cand["x"], cand["y"], cand["z"] = (c + r * n).T
    cand["normal_x"], cand["normal_y"], cand["normal_z"] = n.T
    cand["variance"], cand["kind"] = 1e-4, KIND_CANDIDATE
    return np.concatenate([out, cand])


def test_a_floating_estimate_is_told_from_one_on_the_table():
    found = floating_base(_blob_lattice(0.10), min_z_m=0.015, gap_m=0.03)
    assert found is not None
    centre, radius, z_low = found
    np.testing.assert_allclose(centre, [0.5, 0.0, 0.0], atol=0.011)
    assert 0.02 <= radius <= 0.031 and 0.07 <= z_low <= 0.08  # the lowest node inside the 3 cm ball at 10 cm
    assert floating_base(_blob_lattice(0.025), 0.015, 0.03) is None  # resting on the table
    assert floating_base(_blob_lattice(0.10), 0.015, 0.08) is None  # within the allowed gap
    assert floating_base(_lost_lattice(), 0.015, 0.03) is None  # 2D


@pytest.mark.parametrize("gap", [0.03, 0.0])
def test_the_planner_probes_under_a_floating_estimate_towards_its_footprint(gap):
    """support_gap_m: an estimate floating 7 cm above the table is missing what holds it up: the
    planner probes under it, from a ring round its footprint, towards the footprint's centre;
    with the rule off it touches the ball."""
    params = dict(load_params(str(CONFIG)), mode="3d", strategy="proposed", clearance="mean", support_gap_m=gap)
    planner = TouchPlanner.from_params(params, seed=1)
    res = planner.plan(_map3d(_blob_lattice(0.10)), np.array([0.38, -0.12, 0.15]))
    assert res.ok, res.message
    if gap == 0.0:
        assert not res.message.startswith("search")
        assert abs(np.linalg.norm(res.target_xyz - [0.5, 0.0, 0.10]) - 0.03) < 0.006
        return
    assert res.message.startswith("search under the estimate (it floats"), res.message
    t = res.target_xyz
    assert params["min_tip_z_m"] <= t[2] < 0.07 - 0.02  # below the ball, a pre-touch offset under it
    # on the hemisphere round the footprint's centre on the table, a pre-touch offset (0.02 m) outside
    # the footprint, approached towards that centre
    centre, radius, _ = floating_base(_blob_lattice(0.10), params["min_tip_z_m"], gap)
    assert np.linalg.norm(t - centre) == pytest.approx(radius + 0.02, abs=1e-9)
    np.testing.assert_allclose(res.normal_xyz, (t - centre) / np.linalg.norm(t - centre), atol=1e-9)
