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
