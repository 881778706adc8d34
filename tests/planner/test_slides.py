"""Slide candidates: the traced path on the estimate and the chosen (start, direction, length).

The oracle is analytic: a circle's SDF on the lattice, arcs parametrised by angle, and the
ratio G/T maximised by brute force over an explicit grid of starts, directions and lengths.
"""

from __future__ import annotations

import numpy as np
import pytest

from tactile_common.touch_geometry import MotionModel
from tactile_planner.maps import MapLattice, parse_variance_map
from tactile_planner.planner import TouchPlanner
from tactile_planner.slides import SlideParams, choose_slide, start_directions, start_tangents, trace
from tactile_planner.synthetic import sphere_map

C = np.array([0.5, 0.0])
R = 0.05
Z = 0.06


def circle_lattice(variance_fn, n=129):
    axes = (np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n))
    X, Y = np.meshgrid(*axes, indexing="ij")
    mean = np.hypot(X - C[0], Y - C[1]) - R
    ang = np.arctan2(Y - C[1], X - C[0])
    return MapLattice(axes, mean, variance_fn(ang), Z)


def on_circle(theta):
    theta = np.atleast_1d(theta)
    p = np.column_stack([C[0] + R * np.cos(theta), C[1] + R * np.sin(theta), np.full(len(theta), Z)])
    n = np.column_stack([np.cos(theta), np.sin(theta), np.zeros(len(theta))])
    return p, n


def test_trace_follows_the_circle_counter_clockwise():
    lat = circle_lattice(lambda a: np.full_like(a, 1e-4))
    theta0 = np.array([0.0, 1.0, 2.5, -2.0])
    p, n = on_circle(theta0)
    h, K = 0.003, 60
    pts, var, ok = trace(lat, p, start_tangents(n), h, K)
    assert ok.all() and np.allclose(var, 1e-4)
    r = np.hypot(pts[..., 0] - C[0], pts[..., 1] - C[1])
    assert np.abs(r - R).max() < 2e-4  # on the zero level set (bilinear SDF: corner error O(spacing²/R))
    assert np.allclose(pts[..., 2], Z)
    # arc angle after k steps ≈ k·h / R, counter-clockwise (z × n)
    ang = np.unwrap(np.arctan2(pts[..., 1] - C[1], pts[..., 0] - C[0]), axis=1)
    assert np.allclose(ang[:, -1] - ang[:, 0], K * h / R, rtol=0.02)
    back, _, _ = trace(lat, p, -start_tangents(n), h, K)
    ang_b = np.unwrap(np.arctan2(back[..., 1] - C[1], back[..., 0] - C[0]), axis=1)
    assert np.allclose(ang_b[:, -1] - ang_b[:, 0], -K * h / R, rtol=0.02)


def test_trace_ends_where_it_leaves_the_lattice():
    lat = circle_lattice(lambda a: np.full_like(a, 1e-4))
    p = np.array([[0.5, 0.149, Z]])  # on a level set μ ≠ 0 near the lattice edge: no way back to μ = 0
    pts, var, ok = trace(lat, p, np.array([[1.0, 0.0, 0.0]]), 0.003, 10)
    assert not ok[0, 1:].any()


def brute_force(theta0, variance_of_angle, travel_m, motion, approach_m, params):
    """G/T over starts × directions × lengths on the exact arc (independent of the lattice trace);
    a metre of arc is worth σ² or, with ``value: wrong_surface``, 2Φ(−τ/σ) = erfc(τ/(σ√2))."""
    from math import erfc, sqrt

    if params.value == "wrong_surface":
        worth = np.vectorize(lambda v: erfc(params.known_tolerance_m / sqrt(v) / sqrt(2.0)))
        value_of_angle = lambda a: worth(variance_of_angle(a))  # noqa: E731
    else:
        value_of_angle = variance_of_angle
    h = params.trace_step_m
    K = int(np.floor(params.max_length_m / h + 1e-9))
    k_min = int(np.ceil(params.min_length_m / h - 1e-9))
    best = (-np.inf, None)
    for i, th in enumerate(theta0):
        for d, sgn in enumerate((+1.0, -1.0)):
            ang = th + sgn * np.arange(K + 1) * h / R
            gain = np.cumsum(value_of_angle(ang) * h)
            for k in range(k_min, K + 1):
                T = travel_m[i] / motion.tip_speed_mps + 2 * approach_m / motion.approach_speed_mps \
                    + motion.dwell_s + k * h / motion.slide_speed_mps
                if gain[k] / T > best[0]:
                    best = (gain[k] / T, (i, d, k * h))
    return best


@pytest.mark.parametrize("value", ["variance", "wrong_surface"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_choice_matches_a_brute_force_search(seed, value):
    rng = np.random.default_rng(seed)
    a0 = rng.uniform(-np.pi, np.pi)

    def variance_of_angle(a):  # a bump of uncertainty around a0 over a low floor
        return 1e-6 + 1e-3 * np.exp(-0.5 * (np.angle(np.exp(1j * (a - a0))) / 0.5) ** 2)

    lat = circle_lattice(variance_of_angle, n=257)
    theta0 = np.linspace(-np.pi, np.pi, 24, endpoint=False)
    p, n = on_circle(theta0)
    travel = rng.uniform(0.0, 0.2, len(theta0))
    motion = MotionModel(slide_speed_mps=0.05)
    params = SlideParams(max_length_m=0.25, min_length_m=0.02, trace_step_m=0.002, value=value)
    choice = choose_slide(lat, p, n, np.ones(len(p), bool), travel, motion, 0.01, params)
    ratio, (i, d, length) = brute_force(theta0, variance_of_angle, travel, motion, 0.01, params)
    assert choice.score == pytest.approx(ratio, rel=0.03)
    assert choice.index == i
    sign = 1.0 if d == 0 else -1.0
    assert np.allclose(choice.direction_xyz, sign * start_tangents(n[i:i + 1])[0], atol=1e-9)
    assert choice.length_m == pytest.approx(length, abs=3 * params.trace_step_m)
    # the path runs into the bump and stops past it, not a whole lap
    assert choice.length_m < 0.25


def test_uniform_variance_slides_the_longest():
    lat = circle_lattice(lambda a: np.full_like(a, 1e-4))
    p, n = on_circle(np.linspace(0, 2 * np.pi, 8, endpoint=False))
    params = SlideParams(max_length_m=0.2, min_length_m=0.02, trace_step_m=0.003)
    c = choose_slide(lat, p, n, np.ones(8, bool), np.linspace(0.05, 0.12, 8), MotionModel(), 0.01, params)
    assert c.index == 0 and c.length_m == pytest.approx(0.2, abs=0.003)  # the nearest start, full length


def test_no_reachable_candidate_gives_no_slide():
    lat = circle_lattice(lambda a: np.full_like(a, 1e-4))
    p, n = on_circle(np.array([0.0, 1.0]))
    c = choose_slide(lat, p, n, np.zeros(2, bool), np.zeros(2), MotionModel(), 0.01, SlideParams())
    assert c.index == -1 and not np.isfinite(c.length_m) and np.all(np.isinf(c.scores))


def test_bad_slide_params_are_refused():
    with pytest.raises(ValueError, match="slide_min_length_m"):
        SlideParams.from_params({"slide_min_length_m": 0.5, "slide_max_length_m": 0.1})
    with pytest.raises(ValueError, match="slide_value"):
        SlideParams.from_params({"slide_value": "fun"})


def test_planner_with_touch_slide_plans_a_tangent_slide():
    m = sphere_map(64, 2, radius_m=0.05)
    params = {"mode": "2d", "touch": "slide", "slide_max_length_m": 0.2}
    res = TouchPlanner(params, seed=0).plan(m, np.array([0.33, 0.0, 0.06]))
    assert res.ok, res.message
    assert 0.02 - 1e-9 <= res.slide_length_m <= 0.2 + 1e-9
    assert np.linalg.norm(res.slide_direction_xyz) == pytest.approx(1.0)
    assert abs(res.slide_direction_xyz @ res.normal_xyz) < 1e-6  # along the surface
    poke = TouchPlanner({"mode": "2d"}, seed=0).plan(m, np.array([0.33, 0.0, 0.06]))
    assert poke.ok and np.isnan(poke.slide_length_m)
    _, cands = parse_variance_map(m)
    assert res.index < len(cands)


def test_3d_start_directions_span_the_tangent_plane():
    n = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.6, 0.8]])  # a wall, a top, a slope
    d = start_directions(n, 4)
    assert d.shape == (3, 4, 3)
    assert np.allclose(np.linalg.norm(d, axis=2), 1.0) and np.allclose(np.einsum("mkj,mj->mk", d, n), 0.0)
    # the wall: along the horizontal band (z × n = +y) first, then up the surface (+z), then back, then down
    assert np.allclose(d[0], [[0, 1, 0], [0, 0, 1], [0, -1, 0], [0, 0, -1]], atol=1e-12)
    two = start_directions(n, 2)
    assert np.allclose(two[:, 0], d[:, 0]) and np.allclose(two[:, 1], -d[:, 0])
    assert np.allclose(two[[0, 2], 0], start_tangents(n[[0, 2]]))  # D = 2 is the band of before
    assert np.allclose(d[2, 0], [-1, 0, 0]) and d[2, 1, 2] > 0  # the slope: horizontal, then uphill


def test_a_3d_trace_stops_at_the_lowest_tip_height():
    m = parse_variance_map(sphere_map(40, 3, radius_m=0.05))[0]
    c = np.array([0.5, 0.0, 0.06])  # sphere_map's default centre
    start = c + np.array([0.05, 0.0, 0.0])
    down = np.array([[0.0, 0.0, -1.0]])
    pts, _, ok = trace(m, start[None], down, 0.003, 30, min_z_m=0.03)
    valid = np.cumprod(ok, axis=1).astype(bool)[0]
    assert valid[:5].all() and not valid.all()
    assert pts[0, valid, 2].min() >= 0.03 and pts[0, np.argmin(valid), 2] < 0.03


def _rod_clear_of_sphere(c, radius_m, tip_radius_m, gap_m):
    """The vertical rod above the tip centre x + r·n clears the sphere (c, R) by ``gap_m`` (analytic)."""
    def ok(x, n):
        tip = x + tip_radius_m * n
        rho = np.hypot(tip[:, 0] - c[0], tip[:, 1] - c[1])
        top = c[2] + np.sqrt(np.maximum(radius_m ** 2 - rho ** 2, 0.0))  # the sphere's top above the tip
        return (rho >= radius_m + gap_m) | (tip[:, 2] >= top)
    return ok


def test_a_3d_trace_heading_down_goes_on_straight_down_where_the_estimate_turns_under_the_rod():
    """Down a sphere from its equator: the surface turns under the rod at cos φ = (R + gap)/(R + r)
    (φ below the equator); from the last point the rod clears, the path goes straight down to the
    lowest tip height (a wall the estimate has not seen yet is what the finger would find there)."""
    m = parse_variance_map(sphere_map(48, 3, radius_m=0.05))[0]
    c = np.array([0.5, 0.0, 0.06])
    R, r, gap, h, z_min = 0.05, 0.01, 0.002, 0.002, 0.015
    ok_fn = _rod_clear_of_sphere(c, R, r, gap)
    start = c + np.array([R, 0.0, 0.0])
    pts, _, ok = trace(m, start[None], np.array([[0.0, 0.0, -1.0]]), h, 60, min_z_m=z_min, surface_ok=ok_fn)
    valid = np.cumprod(ok, axis=1).astype(bool)[0]
    p = pts[0, valid]
    assert p[-1, 2] >= z_min and p[-1, 2] < z_min + h + 1e-9  # down to the lowest tip height
    phi = np.arcsin(np.clip((c[2] - p[:, 2]) / R, -1, 1))  # angle below the equator where on the sphere
    on_sphere = np.abs(np.linalg.norm(p - c, axis=1) - R) < 5e-4
    turn = np.flatnonzero(~on_sphere)[0]  # the first point off the sphere: straight down from here
    phi_turn = np.arccos((R + gap) / (R + r))
    assert phi[turn - 1] <= phi_turn + 1e-3 and phi[turn - 1] > phi_turn - 2 * h / R
    np.testing.assert_allclose(p[turn:, :2], np.broadcast_to(p[turn - 1, :2], p[turn:, :2].shape), atol=1e-12)
    np.testing.assert_allclose(np.diff(p[turn - 1:, 2]), -h, atol=1e-12)
    # the same path without the rod check follows the sphere under (and is not cut at the turn)
    free, _, _ = trace(m, start[None], np.array([[0.0, 0.0, -1.0]]), h, 60, min_z_m=z_min)
    assert np.linalg.norm(free[0, turn + 3] - c) == pytest.approx(R, abs=5e-4)


def test_a_3d_trace_along_a_band_the_rod_cannot_follow_ends_there():
    """Horizontal, below the equator, where the rod would enter the sphere: no drop (it is not heading
    down), the path ends at its start."""
    m = parse_variance_map(sphere_map(48, 3, radius_m=0.05))[0]
    c = np.array([0.5, 0.0, 0.06])
    phi = np.radians(50.0)
    start = c + 0.05 * np.array([np.cos(phi), 0.0, -np.sin(phi)])
    _, _, ok = trace(m, start[None], np.array([[0.0, 1.0, 0.0]]), 0.002, 20, min_z_m=0.015,
                     surface_ok=_rod_clear_of_sphere(c, 0.05, 0.01, 0.002))
    assert np.cumprod(ok, axis=1).astype(bool)[0].sum() == 1
