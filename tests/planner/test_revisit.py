"""Targets already chosen are not chosen again; 3D candidates a vertical finger cannot touch are skipped."""

import numpy as np
import pytest

from tactile_common.touch_geometry import APPROACH_BOX_INSET_M
from tactile_planner.planner import TouchPlanner
from tactile_planner.synthetic import sphere_map


def test_same_map_twice_gives_a_new_target_far_enough():
    m = sphere_map(96, 2, seed=1)
    planner = TouchPlanner.from_params({"mode": "2d", "strategy": "uncertainty", "revisit_radius_m": 0.005}, seed=0)
    tip = np.array([0.33, 0.0, 0.06])
    first = planner.plan(m, tip)
    second = planner.plan(m, tip)
    assert first.ok and second.ok
    assert np.linalg.norm(second.target_xyz - first.target_xyz) > 0.005
    # Without the memory the most uncertain point is chosen again.
    planner.reset()
    assert np.allclose(planner.plan(m, tip).target_xyz, first.target_xyz)
    off = TouchPlanner.from_params({"mode": "2d", "strategy": "uncertainty", "revisit_radius_m": 0.0,
                                    "fruitless_radius_m": 0.0}, seed=0)
    assert np.allclose(off.plan(m, tip).target_xyz, off.plan(m, tip).target_xyz)


def _sphere_candidates(center, radius_m, n):
    """Candidates spread over the whole sphere above z = 0.02 (a Fibonacci lattice)."""
    from tactile_common.fields import KIND_CANDIDATE, VARIANCE_MAP_DTYPE

    k = np.arange(n) + 0.5
    phi, th = np.arccos(1 - 2 * k / n), np.pi * (1 + 5**0.5) * k
    nrm = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], axis=1)
    p = np.asarray(center) + radius_m * nrm
    keep = p[:, 2] > 0.02
    cand = np.zeros(int(keep.sum()), VARIANCE_MAP_DTYPE)
    for i, f in enumerate("xyz"):
        cand[f] = p[keep, i]
        cand["normal_" + f] = nrm[keep, i]
    cand["variance"] = np.random.default_rng(3).uniform(1e-5, 1e-3, len(cand))
    cand["kind"] = KIND_CANDIDATE
    return cand


def test_3d_candidates_facing_down_are_skipped():
    center = (0.5, 0.0, 0.10)
    m = sphere_map(40, 3, center=center, n_candidates=1, seed=2)
    cand = _sphere_candidates(center, 0.05, 300)
    m = np.concatenate([m[m["kind"] == 0], cand])
    assert (cand["normal_z"] < -0.2).sum() > 50
    tip = np.array([0.33, 0.0, 0.15])
    planner = TouchPlanner.from_params({"mode": "3d", "strategy": "uncertainty", "min_normal_z": -0.2}, seed=0)
    allowed = cand["normal_z"] >= -0.2
    best_allowed = cand[allowed][np.argmax(cand["variance"][allowed])]
    res = planner.plan(m, tip)
    assert res.ok and np.allclose(res.target_xyz, [best_allowed["x"], best_allowed["y"], best_allowed["z"]])
    off = TouchPlanner.from_params({"mode": "3d", "strategy": "uncertainty", "min_normal_z": -1.0}, seed=0)
    res = off.plan(m, tip)
    reachable_best = cand[np.argmax(np.where(np.isfinite(res.travel_costs), cand["variance"], -1))]
    assert np.allclose(res.target_xyz, [reachable_best["x"], reachable_best["y"], reachable_best["z"]])


def test_earlier_targets_are_revisited_rather_than_stopping_when_nothing_else_is_left():
    m = sphere_map(96, 2, seed=1)
    tip = np.array([0.33, 0.0, 0.06])
    # a revisit radius that covers the whole circle: after one decision every candidate is an earlier target
    planner = TouchPlanner.from_params({"mode": "2d", "strategy": "uncertainty", "revisit_radius_m": 0.2}, seed=0)
    first = planner.plan(m, tip)
    second = planner.plan(m, tip)
    assert first.ok and second.ok, second.message
    assert "revisiting" in second.message and "\n" not in second.message
    assert np.allclose(second.target_xyz, first.target_xyz)  # the most uncertain one again
    # a target reported unreachable stays excluded (a wall, not a preference)
    c = m[m["kind"] == 1]
    res = planner.plan(m, tip, np.stack([c["x"], c["y"], c["z"]], axis=1))
    assert res.status == "all_unreachable" and "near a target reported unreachable" in res.message


@pytest.mark.parametrize("strategy", ["info_travel", "random", "uncertainty"])
def test_a_fresh_planner_told_the_history_decides_as_the_one_that_lived_through_it(strategy):
    """The planner's only memory is the targets chosen so far and its judgment of them (fruitless touches,
    the last target's variance), and the k-th decision's random draws come from (seed, k): a planner
    restarted mid-run and given that history makes the same touch sequence."""
    maps = [sphere_map(96, 2, seed=s) for s in (1, 2, 3, 4, 5)]
    tip = np.array([0.33, 0.0, 0.06])
    params = {"mode": "2d", "strategy": strategy, "revisit_radius_m": 0.005, "fruitless_radius_m": 0.02}
    lived = TouchPlanner.from_params(params, seed=7)
    answers = [lived.plan(m, tip) for m in maps]
    targets = [a.target_xyz for a in answers]
    assert any(len(a.fruitless_xyz) for a in answers)  # the fruitless judgment is part of the memory here
    history, judged = [], (None, None)
    for m, expected in zip(maps, targets):
        fresh = TouchPlanner.from_params(params, seed=7)
        res = fresh.plan(m, tip, None, np.array(history).reshape(-1, 3), 0, *judged)
        assert res.ok and np.array_equal(res.target_xyz, expected)
        history.append(res.target_xyz)
        judged = (res.fruitless_xyz, res.target_var_m2)  # what the answer hands back
    assert len({tuple(t) for t in targets}) == len(targets)  # the memory mattered: no target twice
    # without the history a restarted planner repeats itself (what the history prevents)
    assert np.array_equal(TouchPlanner.from_params(params, seed=7).plan(maps[0], tip).target_xyz, targets[0])


def test_3d_candidates_the_tip_would_touch_below_the_lowest_tip_height_are_skipped():
    """The shortest approach worth making (standoff + half the depth, and the commander's inset
    ``APPROACH_BOX_INSET_M``) from the pre-touch point c + (standoff + r)·n ends at
    c + (r − depth/2 − inset)·n; below ``min_tip_z_m`` (the commander's box floor) the commander refuses
    the touch: not chosen."""
    center = (0.5, 0.0, 0.10)
    m = sphere_map(40, 3, center=center, n_candidates=1, seed=2)
    cand = _sphere_candidates(center, 0.05, 300)
    r, standoff, depth, floor = 0.010, 0.010, 0.030, 0.015
    rim = np.arange(0, len(cand), 6)[:40]  # candidates of every orientation moved near the table,
    cand["z"][rim] = 0.018  # the most uncertain of all: those facing up (n_z > 0.6) cannot be probed
    cand["variance"][rim] = 1.0
    low = cand["z"] + (r - depth / 2 - APPROACH_BOX_INSET_M) * cand["normal_z"] < floor
    assert 5 < low[rim].sum() < 35
    m = np.concatenate([m[m["kind"] == 0], cand])
    planner = TouchPlanner.from_params({"mode": "3d", "strategy": "uncertainty", "min_normal_z": -1.0,
                                        "tip_radius_m": r, "standoff_m": standoff, "max_depth_m": depth,
                                        "min_tip_z_m": floor}, seed=0)
    res = planner.plan(m, np.array([0.33, 0.0, 0.15]))
    assert res.ok and res.target_xyz[2] + (r - depth / 2 - APPROACH_BOX_INSET_M) * res.normal_xyz[2] >= floor
    assert res.target_xyz[2] == pytest.approx(0.018)  # a rim candidate the tip can probe was chosen
    assert np.array_equal(planner.last_why["touched below the lowest tip height"], low)


def test_a_target_is_revisited_once_not_again_and_again():
    """When only earlier targets are left one is revisited (the run goes on), but not a third time: a flat
    object's run had revisited one target 40 times, its path meeting the object at the same point."""
    m = sphere_map(64, 2, seed=1)
    cands = m[m["kind"] == 1]
    one = np.concatenate([m[m["kind"] == 0], cands[:1]])
    planner = TouchPlanner.from_params({"mode": "2d", "strategy": "uncertainty", "search_quantile": 0.0}, seed=0)
    tip = np.array([0.33, 0.0, 0.06])
    first, second, third = (planner.plan(one, tip) for _ in range(3))
    assert first.ok and "revisiting" not in first.message
    assert second.ok and "revisiting" in second.message
    assert np.allclose(second.target_xyz, first.target_xyz)
    assert not third.ok and "targeted twice already" in third.message, third.message
