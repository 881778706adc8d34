"""Shape accuracy of an estimate against the simulated object (docs/architecture.md, Metrics).

IoU of the estimated solid {μ < 0} against the true solid on a fixed lattice
over the estimator's workspace (z ≥ 0 in 3D), and the mean distance from the
true surface to the estimated zero level set.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from tactile_sim import metrics
from tactile_sim.objects import SDFObject, make_object


class Evaluator:
    """Ground truth of one experiment and the metrics of an estimate against it."""

    def __init__(self, experiment, obj: Optional[SDFObject] = None) -> None:
        self.obj = obj if obj is not None else make_object(
            experiment.object_name, mode=experiment.mode, **experiment.object_pose_kwargs())
        self.points = metrics.evaluation_lattice(experiment.evaluation_bounds(),
                                                 experiment.evaluation_resolution_m)
        self.true_surface = metrics.true_surface_samples(self.obj)

    def iou(self, estimator) -> float:
        """IoU of {μ < 0}, μ interpolated from the estimator's lattice (cheap after every touch)."""
        return metrics.iou(estimator.lattice_inside, self.obj, self.points)

    def surface_error_m(self, estimator) -> Optional[float]:
        surface = estimator.surface_points()
        if len(surface) == 0:
            return None
        return metrics.surface_error(self.obj, surface[:, : self.obj.dim])
