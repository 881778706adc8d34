"""The offline rig (tactile_bringup.rig_touch): the commander's pokes on the simulated rig, in one process.

Judged against the analytic circle (centre (0.50, 0.00), radius 4 cm: its SDF
and normal are |p − c| − r and (p − c)/|p − c|), the touch geometry's own
lengths, and the workspace box, not against the code's own output.
"""

import numpy as np
import pytest

from tactile_bringup.experiment import Experiment
from tactile_bringup.rig_touch import RigFinger
from tactile_planner.planner import PlanResult
from tactile_sim.objects import make_object

CENTRE = np.array([0.50, 0.0, 0.06])
RADIUS_M = 0.04


def _circle_sdf(p: np.ndarray) -> float:
    return float(np.linalg.norm((np.asarray(p) - CENTRE)[:2]) - RADIUS_M)


@pytest.fixture(scope="module")
def experiment():
    return Experiment(mode="2d", object_name="circle", touches=1, seed=3)


def _rig(experiment) -> RigFinger:
    return RigFinger(experiment, make_object("circle", mode="2d"))


def _plan(rig: RigFinger, target_xyz, normal_xyz) -> PlanResult:
    """A decision from the start position straight to the pre-touch point of the target."""
    target, normal = np.asarray(target_xyz, float), np.asarray(normal_xyz, float)
    pretouch = rig.geometry.pretouch_xyz(target, normal)
    path = np.vstack([rig.motions.model.fk(rig.q)[0], pretouch])
    return PlanResult("ok", "", 0, target, normal, pretouch, path)


def test_a_poke_on_the_circle_senses_its_surface_and_ends_at_the_pre_touch_point(experiment):
    rig = _rig(experiment)
    touched = []
    for angle in np.radians([180.0, 150.0, 215.0]):  # faces the start side: free paths
        n = np.array([np.cos(angle), np.sin(angle), 0.0])
        res = rig.poke(_plan(rig, CENTRE + RADIUS_M * n, n))
        assert res.outcome == "contact" and res.path_followed_m is None, res
        assert abs(_circle_sdf(res.point_xyz)) < 1e-3, res.point_xyz
        true_n = (res.point_xyz - CENTRE) * [1, 1, 0] / np.linalg.norm((res.point_xyz - CENTRE)[:2])
        assert float(res.normal_xyz @ true_n) > np.cos(np.radians(10))
        assert abs(res.point_xyz[2] - CENTRE[2]) < 1e-3  # the 2D rig senses at the tip's height
        pretouch = rig.geometry.pretouch_xyz(CENTRE + RADIUS_M * n, n)
        assert np.array_equal(res.end_xyz, pretouch)
        # the approach went from the pre-touch point about (standoff + tip radius) to the surface
        assert 0.0 < res.approach_m < rig.geometry.approach_length_m
        touched.append(res.point_xyz)
    # the arm ends each touch at the joints of its pre-touch point (the next one plans from there)
    assert np.linalg.norm(rig.motions.model.fk(rig.q)[0] - pretouch) < 2e-4


def test_an_approach_into_free_space_reports_the_probe_end_and_its_sweep(experiment):
    rig = _rig(experiment)
    n = np.array([-1.0, 0.0, 0.0])
    target = CENTRE + (RADIUS_M + 0.05) * n  # 5 cm short of the circle: nothing within the approach
    res = rig.poke(_plan(rig, target, n))
    assert res.outcome == "free_space", res
    pretouch = rig.geometry.pretouch_xyz(target, n)
    expected_end = pretouch - rig.geometry.approach_length_m * n
    assert np.linalg.norm(res.point_xyz - expected_end) < 2e-4  # IK tolerance (1e-4) twice
    assert np.linalg.norm(res.point_xyz + res.sweep_xyz - pretouch) < 2e-4
    assert _circle_sdf(res.point_xyz) > 0


def test_a_path_through_the_object_stops_on_its_contact_and_backs_off_into_free_space(experiment):
    rig = _rig(experiment)
    n = np.array([1.0, 0.0, 0.0])  # the far side: the straight path crosses the circle
    res = rig.poke(_plan(rig, CENTRE + RADIUS_M * n, n))
    assert res.outcome == "contact" and res.path_followed_m is not None, res
    assert abs(_circle_sdf(res.point_xyz)) < 1e-3 and res.point_xyz[0] < CENTRE[0]  # the near side
    # followed from the start to where the skin met the circle (centre x − r − tip radius)
    first_touch_m = (CENTRE[0] - RADIUS_M - 0.010) - experiment.start_tip_xyz[0]
    assert first_touch_m - 2e-3 < res.path_followed_m < first_touch_m + 2e-3
    assert _circle_sdf(res.end_xyz) > 0.010  # backed off: the tip (radius 1 cm) is clear
    assert res.end_xyz[0] < res.point_xyz[0]


def test_an_unreachable_goal_moves_nothing(experiment):
    rig = _rig(experiment)
    q = rig.q.copy()
    n = np.array([-1.0, 0.0, 0.0])
    res = rig.poke(_plan(rig, np.array([0.95, 0.0, 0.06]), n))  # outside the commander's box (x ≤ 0.75)
    assert res.outcome == "unreachable" and "box" in res.reason.lower(), res.reason
    assert np.array_equal(rig.q, q)


def test_the_same_pokes_sense_the_same_bits(experiment):
    a, b = _rig(experiment), _rig(experiment)
    for angle in np.radians([160.0, 200.0]):
        n = np.array([np.cos(angle), np.sin(angle), 0.0])
        ra, rb = a.poke(_plan(a, CENTRE + RADIUS_M * n, n)), b.poke(_plan(b, CENTRE + RADIUS_M * n, n))
        assert np.array_equal(ra.point_xyz, rb.point_xyz) and np.array_equal(ra.normal_xyz, rb.normal_xyz)


def test_a_touch_near_the_table_gets_a_shorter_approach_and_one_below_the_floor_is_unreachable():
    """3D: an upward approach onto a low surface would end below the box floor at full depth; it is
    shortened to end inside the box (a free-space probe here: nothing stands on this part of the table).
    A surface so low that the approach could not take the skin half the depth beyond it inside the
    box (TouchGeometry.min_approach_m) is unreachable, nothing moved."""
    rig = RigFinger(Experiment(mode="3d", object_name="sphere", touches=1, seed=0), make_object("sphere", mode="3d"))
    floor = rig.motions.box.lower_xyz[2]
    up = np.array([0.0, 0.0, 1.0])
    low = np.array([0.40, 0.15, 0.03])  # pre-touch at 0.05 m; a full approach would end at 0.01
    assert rig.geometry.pretouch_xyz(low, up)[2] - rig.geometry.approach_length_m < floor
    res = rig.poke(_plan(rig, low, up))
    assert res.outcome == "free_space", res
    assert floor <= res.point_xyz[2] < floor + 1e-3  # the probe ended just inside the box
    assert res.approach_m == pytest.approx(rig.geometry.pretouch_xyz(low, up)[2] - floor, abs=1e-3)
    below = np.array([0.40, 0.15, 0.012])  # pre-touch at 0.032 m: 17 mm to the floor, 25 needed
    assert rig.geometry.pretouch_xyz(below, up)[2] - rig.geometry.min_approach_m < floor
    q = rig.q.copy()
    res = rig.poke(_plan(rig, below, up))
    assert res.outcome == "unreachable" and "outside the safety box" in res.reason, res
    assert np.array_equal(rig.q, q)


def test_an_approach_refused_at_the_end_of_the_path_aborts_the_touch_where_the_arm_stopped(experiment):
    """The commander plans the approach again from where IK put the path's end and ends the touch
    'aborted' when that plan is refused (touch_executor); offline, the arm has then followed the path."""
    from tactile_driver.safety import OutsideWorkspace

    rig = _rig(experiment)
    n = np.array([-1.0, 0.0, 0.0])
    plan = _plan(rig, CENTRE + RADIUS_M * n, n)
    calls, plan_depth = [], rig.motions.approach_depth_m

    def refuse_the_second(start_xyz, direction_xyz, depth_m, min_depth_m=0.0):
        calls.append(start_xyz)
        if len(calls) == 2:
            raise OutsideWorkspace(0, np.asarray(start_xyz), rig.motions.box.lower_xyz, rig.motions.box.upper_xyz)
        return plan_depth(start_xyz, direction_xyz, depth_m, min_depth_m)

    rig.motions.approach_depth_m = refuse_the_second
    res = rig.poke(plan)
    assert res.outcome == "aborted" and res.reason.startswith("approach:") and not res.contact, res
    assert np.linalg.norm(res.end_xyz - plan.pretouch_xyz) < 2e-4  # the path's end (IK tolerance)
    assert np.linalg.norm(rig.motions.model.fk(rig.q)[0] - plan.pretouch_xyz) < 2e-4  # the next touch starts there


def test_a_tilted_poke_senses_the_sphere_and_ends_vertical_at_its_entry():
    """A plan whose path ends tilted (tactile_planner.tilt's form): the rig turns the finger at the entry,
    touches the 3D sphere (radius 5 cm, centre (0.5, 0, 0.05)) with it tilted, and comes back through the
    path's joints to the entry, finger vertical; the way back is counted."""
    from tactile_driver.ik import tilt_of

    exp = Experiment(mode="3d", object_name="sphere", touches=1, seed=3)
    rig = RigFinger(exp, make_object("sphere", mode="3d"))
    centre, n = np.array([0.5, 0.0, 0.05]), np.array([0.0, 1.0, 0.0])
    target = centre + 0.05 * n
    pretouch = rig.geometry.pretouch_xyz(target, n)
    a = np.array([0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    entry = pretouch + 0.03 * a
    here = rig.motions.model.fk(rig.q)[0]
    path = np.vstack([here, entry, entry, pretouch])
    axes = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], a, a])
    res = rig.poke(PlanResult("ok", "", 0, target, n, pretouch, path, path_axes_xyz=axes))
    assert res.outcome == "contact", res
    assert abs(np.linalg.norm(res.point_xyz - centre) - 0.05) < 1e-3 and np.linalg.norm(res.point_xyz - target) < 3e-3
    np.testing.assert_array_equal(res.end_xyz, entry)
    tip, R = rig.motions.model.fk(rig.q)
    assert np.linalg.norm(tip - entry) < 2e-4 and tilt_of(R) <= rig.cfg.max_tilt_rad
    assert res.untilt_m == pytest.approx(np.linalg.norm(pretouch - entry), abs=1e-3) and res.untilt_s > 0
