"""Poke-vs-slide tables: checkpoints along a slide count, laps = travel / contour length."""

from __future__ import annotations

import math

import pytest

from tactile_bringup.slide_tables import first_reaching, per_object, tables
from tactile_sim.contour import contour_length_m, is_convex
from tactile_sim.objects import make_object


def run(obj, strategy, touch, seed, touches, L=0.3):
    return {"object": obj, "strategy": strategy, "touch": touch, "seed": seed, "mode": "2d",
            "contour_length_m": L, "touches": touches, "summary": {"final_iou": touches[-1]["iou"]}}


def t(travel, time, iou, stream=None):
    return {"travel_m": travel, "time_s": time, "iou": iou, "iou_reachable": iou, "stream": stream}


def test_a_checkpoint_inside_a_slide_counts():
    r = run("circle", "s", "slide", 0, [t(0.5, 20.0, 0.97, stream=[{"travel_m": 0.2, "time_s": 8.0, "iou": 0.91,
                                                                      "iou_reachable": 0.91}])])
    assert first_reaching(r, 0.90, "travel_m") == (0.2, True)
    assert first_reaching(r, 0.95, "time_s") == (20.0, True)
    assert first_reaching(r, 0.99, "travel_m") == (0.5, False)  # never: the whole travel


def test_laps_and_time_ratio_against_the_best_poke():
    runs = [run("circle", "a", "poke", s, [t(0.9, 30.0, 0.96)]) for s in range(3)]
    runs += [run("circle", "b", "poke", s, [t(0.6, 20.0, 0.96)]) for s in range(3)]
    runs += [run("circle", "a", "slide", s, [t(0.3, 8.0, 0.96)]) for s in range(3)]
    per = per_object(runs)
    assert per[("circle", "a/slide")][("iou", 0.95, "laps")] == pytest.approx(1.0)
    md = tables(runs)
    assert "| a/slide | 1.00 | — | — | 0.40 | 1 |" in md  # 8 s / the best poke's 20 s


def test_contour_length_and_convexity_of_analytic_sections():
    circle = make_object("circle", mode="2d")
    r = (circle.bounds[1, 0] - circle.bounds[0, 0]) / 2
    assert contour_length_m(circle) == pytest.approx(2 * math.pi * r, rel=1e-3)
    assert is_convex(circle) and not is_convex(make_object("star", mode="2d"))
    with pytest.raises(ValueError, match="2D"):
        contour_length_m(make_object("sphere", mode="3d"))
