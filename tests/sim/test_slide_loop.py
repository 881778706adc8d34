"""The offline loop with --touch slide: one slide senses a circle all round."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tactile_bringup.experiment import Experiment
from tactile_bringup.loop import ExplorationLoop
from tactile_bringup.report import check_report


@pytest.mark.parametrize("touch", ["slide"])
def test_one_slide_touch_senses_the_circle(touch):
    exp = Experiment(mode="2d", object_name="circle", touch=touch, touches=1, seed=0)
    loop = ExplorationLoop(exp)
    report = loop.run()
    check_report(report)
    (t,) = report["touches"]
    assert t["touch"] == "slide" and t["outcome"] == "contact"
    assert t["slide_stop"] in ("lap", "length") and t["slide_m"] > 0.2
    assert t["contacts_gathered"] > 30 and 0 < t["slide_contacts_used"] <= t["contacts_gathered"]
    # robot time ≥ the slide at its speed plus the travel to it at tip speed
    p = exp.planner_params
    assert t["time_s"] >= t["slide_m"] / p["slide_speed_mps"]
    assert t["travel_m"] > t["slide_m"]
    # the streamed contacts lie on the circle and the estimate knows it
    c = np.asarray(t["slide_contacts"])
    obj = loop.evaluator.obj
    assert np.abs(obj.sdf(c[:, :2])).max() < 0.001
    assert t["iou"] > 0.95
    # checkpoints along the slide: travel and time increase, ending before the touch's totals
    s = t["stream"]
    assert len(s) > 3 and all(a["travel_m"] < b["travel_m"] for a, b in zip(s, s[1:]))
    assert s[-1]["travel_m"] < t["travel_m"] and s[-1]["time_s"] < t["time_s"]


def test_poke_is_unchanged_by_the_touch_parameter():
    a = ExplorationLoop(Experiment(mode="2d", object_name="ellipse", touches=2, seed=1)).run()
    b = ExplorationLoop(Experiment(mode="2d", object_name="ellipse", touches=2, seed=1, touch="poke")).run()
    assert [t["travel_m"] for t in a["touches"]] == [t["travel_m"] for t in b["touches"]]
    assert all(t["touch"] == "poke" and t["slide_m"] is None for t in b["touches"])


def test_a_slides_decision_time_leaves_out_the_evaluations_checkpoints():
    # The stream's checkpoints measure the estimate against the true object (simulation only): a
    # touch's decision_ms is the estimator's update and the plan, whatever the evaluation costs.
    loop = ExplorationLoop(Experiment(mode="2d", object_name="circle", touch="slide", touches=1, seed=0))
    slept = []
    for name in ("iou", "iou_reachable"):
        real = getattr(loop.evaluator, name)

        def slow(estimator, real=real):
            time.sleep(0.2)
            slept.append(0.2)
            return real(estimator)

        setattr(loop.evaluator, name, slow)
    (t,) = loop.run()["touches"]
    assert len(t["stream"]) >= 8  # ≥ 16 checkpoint evaluations, ≥ 3.2 s asleep inside the touch's update
    asleep_in_stream_ms = 1e3 * (sum(slept) - 0.2 * 4)  # the prior's and the touch record's evaluations: outside
    assert t["decision_ms"] < asleep_in_stream_ms  # ~0.9 s on a quiet machine, against ≥ 3.2 s
