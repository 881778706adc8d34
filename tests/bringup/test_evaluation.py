"""The metrics read the estimate's own field near its surface, once per estimate."""

import numpy as np
import pytest

from tactile_bringup.cores import make_estimator
from tactile_bringup.evaluation import Evaluator
from tactile_bringup.experiment import Experiment
from tactile_sim import metrics


def _estimate(exp: Experiment):
    est = make_estimator(exp)
    for a in np.linspace(0, 2 * np.pi, 7, endpoint=False):
        n = np.array([np.cos(a), np.sin(a), 0.0])
        est.add_observation(np.array([0.5, 0.0, 0.06]) + 0.04 * n, n, 1)
    return est


def _counting_field_calls(est) -> list:
    calls = []
    refined = est.refined_mean
    est.refined_mean = lambda p: calls.append(len(p)) or refined(p)
    return calls


def test_cell_centres_count_the_gp_means_sign_once_per_estimate():
    exp = Experiment(mode="2d", object_name="ellipse", touches=1, seed=0)
    exp.evaluation_partial_volume = False
    est, ev = _estimate(exp), Evaluator(exp)
    calls = _counting_field_calls(est)
    iou, reach = ev.iou(est), ev.iou_reachable(est)
    assert len(calls) == 1  # both IoUs read one field
    # against the GP's own inside test, point by point (an independent evaluation)
    assert iou == metrics.iou(est.inside, ev.obj, ev.points)
    assert reach == metrics.reachable_iou(est.inside, ev.obj, ev.points, ev.tip_radius_m, ev.min_tip_z_m)
    est.add_observation(np.array([0.5, 0.045, 0.06]), np.array([0.0, 1.0, 0.0]), 1)
    assert ev.iou(est) == metrics.iou(est.inside, ev.obj, ev.points) and len(calls) == 2  # a new estimate


def test_the_default_counts_partial_volumes_of_the_gp_mean():
    exp = Experiment(mode="2d", object_name="ellipse", touches=1, seed=0)
    assert exp.evaluation_partial_volume  # the default (explorer.yaml)
    est, ev = _estimate(exp), Evaluator(exp)
    calls = _counting_field_calls(est)
    iou, reach = ev.iou(est), ev.iou_reachable(est)
    assert len(calls) == 1
    # the GP mean itself at every lattice point (dense predictions, not the estimator's lattice)
    mean = est.predict(np.column_stack([ev.points, np.full(len(ev.points), 0.06)]))[0]
    assert iou == pytest.approx(metrics.partial_volume_iou(mean, ev.obj, ev.points), abs=1e-3)
    assert reach == pytest.approx(metrics.partial_volume_iou(mean, ev.obj, ev.points, ev.tip_radius_m), abs=1e-3)
    assert 0.5 < iou < 1.0


def test_the_rods_true_clearance_is_the_distance_from_the_rod_to_the_sphere_less_its_radius():
    """The default sphere (radius 5 cm, centre (0.5, 0, 0.05)): a vertical rod beside it at horizontal
    distance d from the centre clears it by d − R; one that rises through it is as deep as its centre."""
    exp = Experiment(mode="3d", object_name="sphere", touches=1, seed=0)
    ev = Evaluator(exp)
    R, rs, centre = 0.05, ev.shaft_radius_m, np.array([0.5, 0.0, 0.05])
    beside = np.array([[0.5 + 0.07, -0.05, 0.02], [0.5 + 0.07, 0.05, 0.02]])  # the rod spans z = 0.05 at x = c + 7 cm
    assert ev.shaft_clearance_m(beside) == pytest.approx(0.07 - R - rs, abs=1e-5)
    # the track passes 7 cm from the centre at its nearest (y = 0): the rod is 2 cm off the surface there
    under = np.array([[0.62, 0.0, 0.016], [0.50, 0.0, 0.016]])  # under the ball to its axis (a rod sample at z = 0.05)
    assert ev.shaft_clearance_m(under) == pytest.approx(-R - rs, abs=1e-5)
    assert ev.shaft_clearance_m(np.zeros((0, 3))) is None
    assert Evaluator(Experiment(mode="2d", object_name="ellipse", touches=1, seed=0)).shaft_clearance_m(beside) is None
    assert 0.016 + 0.01 < centre[2] < 0.016 + 0.16  # the rod (from the tip's top to the flange) spans the centre


def test_the_summary_counts_the_touches_whose_rod_entered_the_object():
    from tactile_bringup.report import summarise

    touches = [{"travel_m": 0.1 * i, "time_s": i, "iou": 0.5, "iou_reachable": 0.5, "shaft_clearance_m": c}
               for i, c in enumerate([0.004, -0.002, 0.0049, -0.01])]
    assert summarise(touches, 0.1, "touch budget")["shaft_collisions"] == 2
    for t in touches:
        t["shaft_clearance_m"] = None  # 2D
    assert summarise(touches, 0.1, "touch budget")["shaft_collisions"] is None


def test_the_tip_track_of_a_touch_ends_where_the_tip_centre_met_the_surface():
    from types import SimpleNamespace

    from tactile_bringup.progress import _tip_points as _tip_track

    path = [[0.40, 0.0, 0.10], [0.50, 0.0, 0.10]]
    c = np.array([0.50, 0.0, 0.08])
    got = _tip_track(path, True, c, [0.0, 0.0, 2.0], None, 0.01)  # any length of normal
    np.testing.assert_allclose(got, [path[0], path[1], [0.50, 0.0, 0.09]])
    # no normal (a rim contact): r back along the approach, towards where it began
    np.testing.assert_allclose(_tip_track(path, True, c, [np.nan] * 3, None, 0.01)[-1], [0.50, 0.0, 0.09])
    np.testing.assert_allclose(_tip_track(path, False, c, None, None, 0.01)[-1], c)  # a miss: the probe's end
    slide = SimpleNamespace(n_contacts=2, points_xyz=np.array([[0.5, 0.01, 0.08], [0.5, 0.02, 0.08]]),
                            normals_xyz=np.array([[1.0, 0, 0], [np.nan, 0, 0]]))
    got = _tip_track(path, True, c, [0.0, 0.0, 1.0], slide, 0.01)
    np.testing.assert_allclose(got[-1], [0.51, 0.01, 0.08])  # the slide's contact with a normal, not the other
    assert len(got) == 4


def test_a_tilted_rod_is_checked_along_its_axis_and_while_it_turns():
    from tactile_bringup.evaluation import Evaluator
    from tactile_bringup.experiment import Experiment

    ev = Evaluator(Experiment(mode="3d", object_name="sphere", touches=1, seed=0))
    R, rs, L, r = 0.05, ev.shaft_radius_m, ev.shaft_length_m, ev.tip_radius_m
    c = np.array([0.5, 0.0, 0.05])  # the default sphere (centre, radius) the other rod test uses
    tip = c + np.array([0.0, 0.0, -0.07])  # 2 cm under the ball: a vertical rod goes through it
    assert ev.shaft_clearance_m(tip[None]) == pytest.approx(-R - rs, abs=1e-5)
    # horizontal along +x: the rod's nearest point to the centre is its start (r past the tip): closed form
    flat = np.array([1.0, 0.0, 0.0])
    want = np.hypot(0.07, r) - R - rs
    assert ev.shaft_clearance_m(tip[None], axes_xyz=flat[None]) == pytest.approx(want, abs=2e-4)
    # turning in place from horizontal to vertical sweeps the rod through the ball
    assert ev.shaft_clearance_m(np.vstack([tip, tip]), axes_xyz=np.vstack([flat, [0, 0, 1.0]])) < -R / 2
    # moving along its own axis (an insertion) keeps the clearance of the nearest point on the line
    along = np.vstack([tip + 0.05 * flat, tip])
    assert ev.shaft_clearance_m(along, axes_xyz=np.vstack([flat, flat])) == pytest.approx(want, abs=2e-4)
    assert L > 0.07


def test_the_tip_track_carries_the_finger_axis_to_the_approachs_end():
    from tactile_bringup.progress import _tip_track

    path = [[0.40, 0.0, 0.10], [0.40, 0.0, 0.10], [0.45, 0.0, 0.10]]
    axes = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]
    track, A = _tip_track(path, True, np.array([0.50, 0.0, 0.10]), [-1.0, 0.0, 0.0], None, 0.01, axes)
    assert len(track) == len(A) == 4
    np.testing.assert_allclose(A[-1], [-1.0, 0.0, 0.0])
    assert _tip_track(path, True, np.array([0.50, 0.0, 0.10]), [-1.0, 0.0, 0.0], None, 0.01)[1] is None


def test_the_wrist_of_a_tilted_finger_is_measured_against_the_table_and_the_object():
    from tactile_bringup.evaluation import Evaluator
    from tactile_bringup.experiment import Experiment
    from tactile_bringup.report import summarise
    from tactile_planner.wrist import PANDA_WRIST_BANDS_M

    ev = Evaluator(Experiment(mode="3d", object_name="sphere", touches=1, seed=0))
    L = ev.shaft_length_m
    tip = np.array([[0.40, 0.0, 0.12]])
    assert ev.wrist_clearance_m(tip, np.array([[0.0, 0.0, 1.0]])) is None  # vertical: not measured
    assert ev.wrist_clearance_m(tip, None) is None
    # tilted 60 deg away from the sphere: the table binds, at the lowest rim point of a band (closed form)
    a = np.array([-np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)])
    want = min(0.12 + (L + t0) * a[2] - rho * np.sin(np.pi / 3) for t0, _, rho in PANDA_WRIST_BANDS_M)
    assert ev.wrist_clearance_m(tip, a[None]) == pytest.approx(want, abs=1e-9)
    # level 6 cm up: link 6 goes into the table
    level = np.array([[-1.0, 0.0, 0.0]])
    assert ev.wrist_clearance_m(np.array([[0.40, 0.0, 0.06]]), level) == pytest.approx(0.06 - 0.141, abs=1e-9)
    # level at the height of the sphere's centre, pointing at it from 25 cm: the wrist is in the ball
    c = np.array([0.5, 0.0, 0.05])
    assert ev.wrist_clearance_m((c + [-0.25, 0.0, 0.10])[None], np.array([[1.0, 0.0, 0.0]])) < 0
    touches = [{"travel_m": 0.1, "time_s": 1.0, "iou": 0.5, "iou_reachable": 0.5, "wrist_clearance_m": w}
               for w in (None, 0.02, -0.01)]
    assert summarise(touches, 0.1, "touch budget")["wrist_collisions"] == 1
    for t in touches:
        t["wrist_clearance_m"] = None
    assert summarise(touches, 0.1, "touch budget")["wrist_collisions"] is None
