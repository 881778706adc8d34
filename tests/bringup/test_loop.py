"""The offline exploration loop: invariants on a circle, determinism, report schema, tiny grid."""

import json

import numpy as np
import pytest

from tactile_bringup import benchmark
from tactile_bringup.experiment import Experiment
from tactile_bringup.loop import ExplorationLoop
from tactile_bringup.report import auc_travel, check_report, first_reaching, summarise
from tactile_sim.objects import make_object


@pytest.fixture(scope="module")
def circle_run():
    exp = Experiment(mode="2d", object_name="circle", strategy="proposed", touches=8, seed=3)
    loop = ExplorationLoop(exp)
    return exp, loop.run()


def test_loop_invariants_on_a_circle(circle_run):
    exp, report = circle_run
    check_report(report)
    touches = report["touches"]
    assert len(touches) == 8
    travel = np.array([t["travel_m"] for t in touches])
    time_s = np.array([t["time_s"] for t in touches])
    assert np.all(np.diff(travel) > 0) and np.all(np.diff(time_s) > 0), "cumulative travel and time grow"
    circle = make_object("circle", mode="2d")
    tip_r = exp.planner_params["tip_radius_m"]
    for t in touches:
        if t["outcome"] == "contact":
            # On the true surface within the skin's penetration and the sensor noise.
            assert abs(circle.sdf(np.array([t["contact"][:2]]))[0]) < 1.5e-3
            n_true = circle.gradient(np.array([t["contact"][:2]]))[0]
            assert np.dot(n_true, t["normal"][:2]) > np.cos(np.radians(10))
        else:
            # A free-space probe end is the finger centre: the finger never reached the object.
            assert circle.sdf(np.array([t["probe_end"][:2]]))[0] > tip_r - 0.5e-3
    assert sum(t["outcome"] == "contact" for t in touches) >= 6
    assert touches[-1]["iou"] > 0.9, "a circle is easy"
    assert all(t["target"][2] == pytest.approx(exp.gpis_params["plane_z_m"]) for t in touches)
    assert tip_r > 0


def test_same_seed_same_touch_sequence(circle_run):
    exp, report = circle_run
    again = ExplorationLoop(Experiment(mode="2d", object_name="circle", strategy="proposed",
                                       touches=8, seed=3)).run()
    assert [t["target"] for t in again["touches"]] == [t["target"] for t in report["touches"]]
    assert [t["contact"] for t in again["touches"]] == [t["contact"] for t in report["touches"]]


def test_summary_against_hand_computation():
    touches = [{"iou": 0.5, "travel_m": 1.0, "time_s": 10.0},
               {"iou": 0.92, "travel_m": 1.5, "time_s": 14.0},
               {"iou": 0.96, "travel_m": 2.5, "time_s": 20.0}]
    # (1-0.2)*1.0 + (1-0.5)*0.5 + (1-0.92)*1.0
    assert auc_travel(touches, 0.2) == pytest.approx(0.8 + 0.25 + 0.08)
    assert first_reaching(touches, 0.90, "travel_m") == 1.5
    assert first_reaching(touches, 0.95, "time_s") == 20.0
    s = summarise(touches, 0.2, "touch budget")
    assert s["travel_to_iou_0.95_m"] == 2.5 and s["final_iou"] == 0.96 and s["touches"] == 3
    assert summarise(touches[:1], 0.2, "x")["travel_to_iou_0.90_m"] is None
    report = {"touches": touches, "summary": {"prior_iou": 0.2}}
    assert [benchmark.iou_at_travel(report, b) for b in (0.5, 1.0, 1.4, 2.0, 9.0)] == [0.2, 0.5, 0.5, 0.92, 0.96]


def test_bad_choices_are_clear_errors():
    with pytest.raises(ValueError, match="unknown object"):
        ExplorationLoop(Experiment(mode="2d", object_name="no_such_shape", touches=1))
    with pytest.raises(ValueError, match="mode"):
        Experiment(mode="4d")
    with pytest.raises(ValueError, match="no such parameter file"):
        Experiment(mode="2d", user_params_files=["/nonexistent.yaml"])


@pytest.mark.slow
def test_tiny_benchmark_grid(tmp_path, capsys):
    status = benchmark.main(["--mode", "2d", "--objects", "circle,ellipse", "--strategies", "proposed,uncertainty",
                             "--seeds", "1", "--touches", "3", "--jobs", "2", "--out", str(tmp_path)])
    assert status == 0
    runs = json.loads((tmp_path / "runs.json").read_text())
    assert sorted((r["object"], r["strategy"]) for r in runs) == [
        ("circle", "proposed"), ("circle", "uncertainty"), ("ellipse", "proposed"), ("ellipse", "uncertainty")]
    for r in runs:
        check_report(r)
        assert len(r["touches"]) == 3
    md = (tmp_path / "summary.md").read_text()
    assert "| circle | proposed | 1 |" in md and "Whole suite" in md
    for name in ("iou_vs_travel.png", "iou_vs_time.png", "gallery.png"):
        assert (tmp_path / name).stat().st_size > 1000


def test_a_path_through_the_object_stops_on_its_surface_and_backs_off():
    """SimulatedFinger.path_contact against the analytic circle (radius 4 cm at (0.5, 0))."""
    exp = Experiment(mode="2d", object_name="circle", strategy="proposed", touches=1, seed=0)
    loop = ExplorationLoop(exp)
    finger, circle = loop.finger, make_object("circle", mode="2d")
    z = exp.gpis_params["plane_z_m"]
    # A path that passes 1 cm clear of the finger's skin: no contact.
    clear_y = 0.04 + exp.planner_params["tip_radius_m"] + 0.01
    assert finger.path_contact(np.array([[0.40, clear_y, z], [0.60, clear_y, z]]), 0) is None
    # A path with a corner whose second leg crosses the circle off-centre.
    path = np.array([[0.40, 0.10, z], [0.45, 0.02, z], [0.60, 0.02, z]])
    free_m, result, back = finger.path_contact(path, 0)
    assert result.contact
    p = result.point_xyz
    assert abs(circle.sdf(np.array([p[:2]]))[0]) < 2e-3  # on the true surface
    expected = np.array([0.5 - np.sqrt(0.04**2 - 0.02**2), 0.02])  # where the leg meets the circle
    assert np.linalg.norm(p[:2] - expected) < 0.01  # the finger meets it a little earlier (its radius)
    first_leg = np.linalg.norm(path[1] - path[0])
    # Sensed from the last sample whose skin was clear (its bounding radius is larger than the finger's).
    assert first_leg - 0.02 < free_m < first_leg + (expected[0] - 0.45)
    # Backed off: the tip centre at tip radius + standoff from the contact point, clear of the object.
    back_off_m = exp.planner_params["tip_radius_m"] + exp.planner_params["standoff_m"]
    assert np.linalg.norm(back - p) == pytest.approx(back_off_m)
    assert circle.sdf(np.array([back[:2]]))[0] > exp.planner_params["tip_radius_m"] + 0.5 * exp.planner_params["standoff_m"]


def test_touches_aborted_again_and_again_end_the_run_after_the_explorers_retries():
    """An aborted poke (the arm followed the path, the approach was refused) is re-planned from the
    arm's pose, as the explorer re-issues it; after max_retries in a row the run stops and says why."""
    from tactile_bringup.poke_result import PokeResult

    exp = Experiment(mode="2d", object_name="circle", strategy="proposed", touches=5, seed=0)
    loop = ExplorationLoop(exp)
    pokes, ends = [], []

    class RefusingRig:
        def poke(self, plan, tip_xyz=None, touch_index=0):
            pokes.append(np.asarray(tip_xyz, float))
            ends.append(np.asarray(plan.pretouch_xyz, float))
            nan3 = np.full(3, np.nan)
            return PokeResult("aborted", nan3, nan3, 0.0, None, np.asarray(plan.pretouch_xyz, float), None, 0.0,
                              reason="approach: refused")

    loop.poker = RefusingRig()
    report = loop.run()
    assert len(pokes) == loop.max_retries + 1 == 4
    stopped = report["summary"]["stopped_because"]
    assert report["touches"] == [] and "gave up after 3 retries" in stopped and "approach: refused" in stopped, stopped
    assert np.allclose(pokes[0], exp.start_tip_xyz)
    for start, previous_end in zip(pokes[1:], ends):  # re-planned from where the arm stopped
        assert np.array_equal(start, previous_end)
    # The paths followed before each refusal are the run's travel, though no touch recorded them.
    followed = sum(np.linalg.norm(np.diff(np.vstack([a, b]), axis=0)) for a, b in zip(pokes, ends))
    assert report["summary"]["travel_m"] >= followed - 1e-9 > 0
    assert report["summary"]["time_s"] > 0


def test_an_offline_slide_down_a_wall_stops_at_the_commanders_floor():
    """The offline slide keeps the tip centre inside the commander's safety box, floor above the table
    included (table_z + table_margin + tip radius), as the graph's slide does: a slide down the box's
    side wall ends on the box rule there, not on the table or below it."""
    exp = Experiment(mode="3d", object_name="box", strategy="proposed", touches=1, seed=0, touch="slide")
    finger = ExplorationLoop(exp).finger
    arm = exp.arm_params
    floor_m = arm["table_z_m"] + arm["table_margin_m"] + arm["tip_radius_m"]
    approach = finger.approach(np.array([0.40, 0.0, 0.04]), np.array([1.0, 0.0, 0.0]), 0, max_travel_m=0.08)
    assert approach.contact  # the wall at x = 0.46
    result, _ = finger.slide(approach, np.array([0.0, 0.0, -1.0]), 0.10, 0, normal_xyz=np.array([-1.0, 0.0, 0.0]))
    assert result.stop.value == "box"
    assert result.tip_path_xyz[:, 2].min() >= floor_m - 1e-9
    assert result.tip_path_xyz[:, 2].min() < floor_m + 0.002  # it went down to the floor


def test_an_offline_approach_ends_inside_the_commanders_box_as_the_graphs_does():
    """An approach heading down past the floor of the commander's safety box is shortened to end
    APPROACH_BOX_INSET_M inside it (ArmMotions.approach_depth_m): offline the box's wall was found at
    the tip centre's 12 mm (tip 2 mm into the table's margin) where the graph's approach ended above it
    without contact."""
    from tactile_common.touch_geometry import APPROACH_BOX_INSET_M

    exp = Experiment(mode="3d", object_name="box", strategy="proposed", touches=1, seed=0, touch="slide")
    finger = ExplorationLoop(exp).finger
    arm = exp.arm_params
    floor_m = arm["table_z_m"] + arm["table_margin_m"] + arm["tip_radius_m"]
    d = np.array([1.0, 0.0, -1.0]) / np.sqrt(2.0)  # down and towards the wall at x = 0.46
    start = np.array([0.46 - 0.01 - 0.012, 0.0, floor_m + 0.008])  # would meet the wall 3 mm below the floor
    approach = finger.approach(start, d, 0, max_travel_m=0.05)
    assert not approach.contact
    z_end = approach.tip_xyz_at_stop[2]  # the approach moves in sensor-frame steps (0.1 mm)
    assert floor_m <= z_end and z_end == pytest.approx(floor_m + APPROACH_BOX_INSET_M, abs=2e-4)
    assert approach.travel_m == pytest.approx((0.008 - APPROACH_BOX_INSET_M) * np.sqrt(2.0), abs=3e-4)
