"""Shape accuracy of an estimate against the simulated object (docs/architecture.md, Metrics).

IoU of the estimated solid {μ < 0} against the true solid on a fixed lattice
over the estimator's workspace (z ≥ 0 in 3D; μ interpolated from the
estimator's lattice, the GP mean itself within a lattice cell of the surface,
where the interpolation would shrink thin parts: ``ShapeEstimator.refined_mean``;
until 2026-12-05 the interpolated μ everywhere); the same IoU against the
finger-reachable solid (the true solid closed by a ball of the planner's
``tip_radius_m``; in 3D counted above ``min_tip_z_m`` = table + table margin
+ tip radius: :func:`tactile_sim.metrics.reachable_inside`); and the mean
distance from the true surface to the estimated zero level set. With the
explorer's ``evaluation_partial_volume`` (the default since 2026-12-06) a cell a
surface passes through counts by the fraction of it inside, read the same way
from μ and from the true sdf (:func:`tactile_sim.metrics.partial_volume_iou`),
instead of by its centre.

In 3D, the true clearance of the finger's rod over a touch
(:meth:`Evaluator.shaft_clearance_m`): the smallest distance between the true
surface and the vertical rod above the tip (the planner's ``shaft_length_m``,
``shaft_radius_m``) along the tip's path, approach and slide; < 0: the rod went
into the object (a collision on a real rig). For a tilted finger, the same for its wrist
(:meth:`Evaluator.wrist_clearance_m`): the smallest true sdf, or height over the table, on the cylinders
that hold the simulated Panda's link 7 and link 6 (:data:`tactile_common.wrist.PANDA_WRIST_BANDS_M`,
whatever the planner's ``wrist_bands_m``) along the tilted part of the track.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from tactile_common.touch_geometry import rod_points
from tactile_common.wrist import PANDA_WRIST_BANDS_M
from tactile_planner.wrist import band_points
from tactile_driver.trajectory import densify, densify_with_axes
from tactile_sim import metrics
from tactile_sim.objects import SDFObject, make_object


class Evaluator:
    """Ground truth of one experiment and the metrics of an estimate against it."""

    def __init__(self, experiment, obj: Optional[SDFObject] = None) -> None:
        self.obj = obj if obj is not None else make_object(
            experiment.object_name, mode=experiment.mode, **experiment.object_pose_kwargs())
        self.points = metrics.evaluation_lattice(experiment.evaluation_bounds(),
                                                 experiment.evaluation_resolution_m)
        self.partial_volume = bool(getattr(experiment, "evaluation_partial_volume", True))
        self.true_surface = metrics.true_surface_samples(self.obj)
        planner = experiment.planner_params
        self.tip_radius_m = float(planner.get("tip_radius_m", 0.01))
        self.min_tip_z_m = float(planner.get("min_tip_z_m", 0.015)) if self.obj.dim == 3 else None
        self._field_cache: tuple = (None, None, None)  # (estimator, its version, its field on the lattice)
        self.shaft_length_m = float(planner.get("shaft_length_m", 0.16))
        self.shaft_radius_m = float(planner.get("shaft_radius_m", 0.005))
        self.wrist_bands_m = PANDA_WRIST_BANDS_M  # the simulated arm's, whatever the planner assumes

    def _field(self, estimator) -> np.ndarray:
        """The estimate's field on the evaluation lattice (inside where < 0), computed once per estimate
        (both IoUs read it): μ interpolated from the estimator's lattice, the GP mean itself within a
        lattice cell of the surface (``ShapeEstimator.refined_mean``)."""
        version = getattr(estimator, "version", None)  # bumped by every accepted observation
        held, held_version, field = self._field_cache
        if version is None or held is not estimator or held_version != version:
            field = estimator.refined_mean(self.points)
            self._field_cache = (estimator, version, field)
        return field

    def iou(self, estimator) -> float:
        """IoU of {μ < 0} against the true solid (partial volume or cell centres: see the module)."""
        field = self._field(estimator)
        if self.partial_volume:
            return metrics.partial_volume_iou(field, self.obj, self.points)
        return metrics.iou(lambda points: field < 0, self.obj, self.points)

    def iou_reachable(self, estimator) -> float:
        """IoU of {μ < 0} against the finger-reachable solid (fair to a finger of radius r)."""
        field = self._field(estimator)
        if self.partial_volume:
            return metrics.partial_volume_iou(field, self.obj, self.points, self.tip_radius_m, self.min_tip_z_m)
        return metrics.reachable_iou(lambda points: field < 0, self.obj, self.points, self.tip_radius_m,
                                     self.min_tip_z_m)

    def shaft_clearance_m(self, tip_path_xyz: np.ndarray, step_m: float = 0.002,
                          axes_xyz: Optional[np.ndarray] = None) -> Optional[float]:
        """3D: min over the polyline the tip centre followed, (K, 3) world frame sampled every ``step_m``,
        of the true sdf along the rod above the tip (from its top, r past the centre, ``shaft_length_m``
        along the finger axis: vertical, or ``axes_xyz`` (K, 3) at the polyline's points, turning on each
        segment, sampled so that its far end also moves ≤ ``step_m``; every ``step_m``) minus
        ``shaft_radius_m`` (m; < 0: the rod entered the object). None in 2D (the rod stands beside a
        prism's walls) or for an empty path."""
        P = np.asarray(tip_path_xyz, dtype=float).reshape(-1, 3)
        ok = np.isfinite(P).all(axis=1)
        P = P[ok]
        if self.obj.dim != 3 or not len(P) or self.shaft_length_m <= 0:
            return None
        if axes_xyz is None:
            tips, axes = densify(P, step_m), None
        else:
            tips, axes = densify_with_axes(P, np.asarray(axes_xyz, dtype=float).reshape(-1, 3)[ok], step_m,
                                           step_m / self.shaft_length_m)  # the rod's end moves ≤ step_m too
        rod = rod_points(tips, self.tip_radius_m, self.shaft_length_m, step_m, axes)
        return float(np.min(self.obj.sdf(rod.reshape(-1, 3)))) - self.shaft_radius_m

    def wrist_clearance_m(self, tip_path_xyz: np.ndarray, axes_xyz: Optional[np.ndarray],
                          step_m: float = 0.005, table_z_m: float = 0.0) -> Optional[float]:
        """3D, a tilted finger: min over the track's points whose axis leaves vertical (densified as in
        :meth:`shaft_clearance_m`, every ``step_m``) of the true sdf and of the height over the table on
        the wrist's cylinders (:func:`tactile_planner.wrist.band_points`) (m; < 0: the wrist entered the
        object or the table). None in 2D, for a vertical track or an empty one."""
        P = np.asarray(tip_path_xyz, dtype=float).reshape(-1, 3)
        if self.obj.dim != 3 or axes_xyz is None or not len(P):
            return None
        A = np.asarray(axes_xyz, dtype=float).reshape(-1, 3)
        ok = np.isfinite(P).all(axis=1) & np.isfinite(A).all(axis=1)
        tips, axes = densify_with_axes(P[ok], A[ok], step_m, step_m / self.shaft_length_m)
        tilted = axes[:, 2] < np.cos(1e-3)
        if not tilted.any():
            return None
        pts = band_points(tips[tilted], axes[tilted], self.wrist_bands_m, self.shaft_length_m).reshape(-1, 3)
        return float(min(np.min(self.obj.sdf(pts)), np.min(pts[:, 2]) - table_z_m))

    def surface_error_m(self, estimator) -> Optional[float]:
        surface = estimator.surface_points()
        if len(surface) == 0:
            return None
        return metrics.surface_error(self.obj, surface[:, : self.obj.dim])
