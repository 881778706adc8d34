"""Tilted-finger entries: candidates the vertical rod cannot reach, checked against the exact object.

The estimate is the exact mushroom of test_shaft (a 12 × 12 cm deck 2 cm thick at 10–12 cm over a
3 × 3 cm pillar); every entry the planner finds is re-checked here with the exact signed distance,
sampled densely: the rod on the approach, on the insertion line, at the entry and while turning.
"""

import numpy as np
import pytest

from tactile_planner.graph import build_free_graph
from tactile_planner.tilt import TiltSettings, finger_axes, tilted_entries, turn_axes

from test_shaft import mushroom_lattice, mushroom_sdf

R_TIP, STANDOFF, MARGIN, LENGTH = 0.01, 0.01, 0.015, 0.16
ROD_R, GAP = 0.005, 0.002
PATH_NEED, TOUCH_NEED = ROD_R + (MARGIN - R_TIP), ROD_R + GAP
INTERP_TOL_M = 0.002  # the lattice (6.4 mm) field against the exact distance


@pytest.fixture(scope="module")
def graph():
    return build_free_graph(mushroom_lattice(), MARGIN, shell_m=0.03, min_z_m=0.015,
                            shaft_length_m=LENGTH, shaft_clearance_m=PATH_NEED)


def rod_sdf_min(tip, axis, start, stop, step=0.001):
    t = np.arange(start, stop + 1e-12, step)
    return float(mushroom_sdf(np.asarray(tip)[None] + t[:, None] * np.asarray(axis)[None]).min())


def entries_for(graph, target, normal, max_tilt=np.pi / 2, min_flange_z_m=0.0):
    target, normal = np.atleast_2d(target).astype(float), np.atleast_2d(normal).astype(float)
    pre = target + (R_TIP + STANDOFF) * normal
    contact = target + R_TIP * normal
    return pre, contact, tilted_entries(graph, pre, contact, normal, R_TIP, TOUCH_NEED, PATH_NEED, max_tilt,
                                        TiltSettings(min_flange_z_m=min_flange_z_m))


CASES = {
    "deck underside": ((0.46, 0.0, 0.10), (0.0, 0.0, -1.0)),
    "pillar side under the deck": ((0.515, 0.0, 0.05), (1.0, 0.0, 0.0)),
    "pillar front under the deck": ((0.50, -0.015, 0.04), (0.0, -1.0, 0.0)),
}


@pytest.mark.parametrize("case", CASES)
def test_an_entry_under_the_deck_keeps_the_rod_out_of_the_exact_object(graph, case):
    target, normal = CASES[case]
    pre, contact, e = entries_for(graph, target, normal)
    assert e.ok[0], "a tilted finger reaches this candidate"
    a, E, s = e.axis_xyz[0], e.entry_xyz[0], float(e.insert_m[0])
    assert abs(np.linalg.norm(a) - 1) < 1e-12 and a[2] >= -1e-12  # the flange above the tip's height
    # the vertical rod could not: it enters the deck above the pre-touch point
    assert rod_sdf_min(pre[0], (0, 0, 1), R_TIP, LENGTH) < 0
    # approach: the rod along a above every tip centre from p to the expected contact
    for f in np.linspace(0, 1, 21):
        tip = pre[0] + f * (contact[0] - pre[0])
        assert rod_sdf_min(tip, a, R_TIP, LENGTH) >= TOUCH_NEED - INTERP_TOL_M
    # insertion: the entry lies on the axis line; the tip keeps the margin on it, the rod its clearance
    np.testing.assert_allclose(E, pre[0] + s * a, atol=1e-12)
    for f in np.linspace(0, 1, 41):
        tip = pre[0] + f * s * a
        assert mushroom_sdf(tip[None])[0] >= MARGIN - INTERP_TOL_M
    assert rod_sdf_min(pre[0], a, R_TIP, s + LENGTH) >= PATH_NEED - INTERP_TOL_M
    # at the entry the vertical rod is clear, and so is every axis on the turn from +z to a
    for f in np.linspace(0, 1, 31):
        ang = f * np.arccos(a[2])
        h = a[:2] / max(np.linalg.norm(a[:2]), 1e-12)
        axis = np.array([np.sin(ang) * h[0], np.sin(ang) * h[1], np.cos(ang)])
        assert rod_sdf_min(E, axis, R_TIP, LENGTH) >= PATH_NEED - INTERP_TOL_M


@pytest.mark.parametrize("case", CASES)
def test_the_flange_stays_above_its_height_over_the_table(graph, case):
    pre, _, e = entries_for(graph, *CASES[case], min_flange_z_m=0.10)
    if e.ok[0]:
        assert pre[0, 2] + LENGTH * e.axis_xyz[0, 2] >= 0.10
    # under the deck the finger must lie nearly level: its flange would be 8 cm over the table
    assert e.ok[0] == (case != "deck underside")


def test_the_rod_points_out_of_the_side_it_faces(graph):
    _, _, e = entries_for(graph, *CASES["pillar side under the deck"])
    assert e.axis_xyz[0, 0] > 0.5  # towards +x, the way the normal points


def test_no_entry_without_enough_tilt_or_where_none_is_clear(graph):
    _, _, e = entries_for(graph, *CASES["deck underside"], max_tilt=np.pi / 6)
    assert not e.ok[0] and np.isnan(e.axis_xyz[0]).all()
    # under the middle of the deck, against the pillar: no straight way out within 6 cm
    _, _, e = entries_for(graph, (0.50, 0.0, 0.10), (0.0, 0.0, -1.0))
    assert not e.ok[0]


def test_axes_are_ordered_from_the_normal_and_have_the_tilt():
    ax = finger_axes(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]), np.pi / 3, 8)
    np.testing.assert_allclose(np.arccos(ax[..., 2]), np.pi / 3)
    np.testing.assert_allclose(ax[0, 0, :2] / np.linalg.norm(ax[0, 0, :2]), [0.0, 1.0], atol=1e-12)
    off = np.abs(np.angle(np.exp(1j * (np.arctan2(ax[0, 1:, 1], ax[0, 1:, 0]) - np.pi / 2))))
    assert np.all(np.diff(off) >= -1e-12)


def test_turn_axes_lie_on_the_great_circle_within_the_step():
    a = np.array([[np.sin(1.4), 0.0, np.cos(1.4)], [0.0, -1.0, 0.0]])
    t = turn_axes(a, np.pi / 8)
    full = np.concatenate([np.tile([0.0, 0.0, 1.0], (2, 1, 1)), t, a[:, None]], axis=1)
    steps = np.arccos(np.clip((full[:, 1:] * full[:, :-1]).sum(-1), -1, 1))
    assert steps.max() <= np.pi / 8 + 1e-9
    np.testing.assert_allclose(steps.sum(axis=1), np.arccos(a[:, 2]))  # no detour: on the great circle


def test_the_planner_tilts_the_finger_only_for_what_the_vertical_one_cannot_touch():
    from tactile_planner.planner import SHAFT_REASON, TouchPlanner
    from test_shaft import SHAFT, mushroom_map

    cands = np.array([list(CASES["pillar side under the deck"][0]), list(CASES["pillar front under the deck"][0])])
    normals = np.array([list(CASES["pillar side under the deck"][1]), list(CASES["pillar front under the deck"][1])])
    m = mushroom_map(cands, normals)
    tip = np.array([0.62, 0.0, 0.16])
    params = {"mode": "3d", "strategy": "uncertainty", "support_gap_m": 0.0, "search_quantile": 0.0, **SHAFT}
    vertical = TouchPlanner.from_params(params, seed=0)
    res = vertical.plan(m, tip)
    assert not res.ok and vertical.last_why[SHAFT_REASON].all()
    assert len(res.path_axes_xyz) == 0

    planner = TouchPlanner.from_params({**params, "tilt_max_rad": np.pi / 2}, seed=0)
    chosen = set()
    for _ in range(2):
        res = planner.plan(m, tip)
        assert res.ok, res.message
        chosen.add(res.index)
        P, A = res.path_xyz, res.path_axes_xyz
        assert A.shape == P.shape and "finger tilted" in res.message
        # it travels vertical to the entry, turns there, and goes in along the axis to the pre-touch point
        np.testing.assert_array_equal(A[:-2], np.tile([0.0, 0.0, 1.0], (len(A) - 2, 1)))
        np.testing.assert_array_equal(A[-1], A[-2])
        np.testing.assert_array_equal(P[-2], P[-3])
        np.testing.assert_allclose(P[-1], res.pretouch_xyz)
        a = A[-1]
        np.testing.assert_allclose(res.finger_axis_xyz, a)
        s = np.linalg.norm(P[-2] - P[-1])
        np.testing.assert_allclose(P[-2], P[-1] + s * a, atol=1e-12)
        # the vertical part of the path keeps the rod out of the exact deck (sampled every 2 mm)
        seg = np.vstack([u + np.linspace(0, 1, 30)[:, None] * (v - u) for u, v in zip(P[:-3], P[1:-2])])
        rod = seg[:, None, :] + np.arange(R_TIP, LENGTH, 0.002)[None, :, None] * np.array([0, 0, 1.0])
        assert mushroom_sdf(rod.reshape(-1, 3)).min() > 0
    assert chosen == {0, 1}


def test_the_contact_falls_on_the_sensing_side_of_the_tilted_tip(graph):
    """The skin covers the tip's far side from the flange and a band above its equator: the contact, at −n
    from the centre, must make n · a ≥ min_normal_z (for a vertical finger: the "facing down" rule)."""
    target, normal = CASES["deck underside"]
    pre = np.atleast_2d(target) + (R_TIP + STANDOFF) * np.atleast_2d(normal)
    contact = np.atleast_2d(target) + R_TIP * np.atleast_2d(normal)
    n = np.atleast_2d(normal).astype(float)

    def entries(max_tilt, floor):
        return tilted_entries(graph, pre, contact, n, R_TIP, TOUCH_NEED, PATH_NEED, max_tilt,
                              TiltSettings(min_flange_z_m=0.0), floor)

    e = entries(np.pi / 2, -0.2)
    assert e.ok[0] and n[0] @ e.axis_xyz[0] >= -0.2  # only a nearly level finger senses a ceiling
    assert not entries(5 * np.pi / 12, -0.2).ok[0]  # at 75 deg the ceiling would touch the unsensed top
    # a side under the deck faces sideways: a tilt away from it keeps the contact on the skin
    _, _, side = entries_for(graph, *CASES["pillar side under the deck"])
    assert side.ok[0] and CASES["pillar side under the deck"][1] @ side.axis_xyz[0] > 0
