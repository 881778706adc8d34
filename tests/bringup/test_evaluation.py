"""The metrics read the estimate's own inside test near its surface, once per estimate."""

import numpy as np

from tactile_bringup.cores import make_estimator
from tactile_bringup.evaluation import Evaluator
from tactile_bringup.experiment import Experiment
from tactile_sim import metrics


def test_the_iou_is_the_gp_means_and_is_computed_once_per_estimate():
    exp = Experiment(mode="2d", object_name="ellipse", touches=1, seed=0)
    est, ev = make_estimator(exp), Evaluator(exp)
    for a in np.linspace(0, 2 * np.pi, 7, endpoint=False):
        n = np.array([np.cos(a), np.sin(a), 0.0])
        est.add_observation(np.array([0.5, 0.0, 0.06]) + 0.04 * n, n, 1)
    calls = []
    refined = est.refined_inside
    est.refined_inside = lambda p: calls.append(len(p)) or refined(p)
    iou, reach = ev.iou(est), ev.iou_reachable(est)
    assert len(calls) == 1  # both IoUs read one inside test
    # against the GP's own inside test, point by point (an independent evaluation)
    assert iou == metrics.iou(est.inside, ev.obj, ev.points)
    assert reach == metrics.reachable_iou(est.inside, ev.obj, ev.points, ev.tip_radius_m, ev.min_tip_z_m)
    est.add_observation(np.array([0.5, 0.045, 0.06]), np.array([0.0, 1.0, 0.0]), 1)
    assert ev.iou(est) == metrics.iou(est.inside, ev.obj, ev.points) and len(calls) == 2  # a new estimate
