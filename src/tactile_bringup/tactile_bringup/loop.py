"""The exploration loop, ROS-free: the node graph's touch cycle run in one process.

estimate → candidates → plan → move along the path → guarded approach along
−normal until the finger's surface meets the object (contact) or a maximum
depth (free space) → retract → update. It uses the same cores with the same
parameters as the nodes (``ShapeEstimator`` = gpis_estimator,
``TouchPlanner`` = soc_planner, ``simulate_approach`` with the driver's
``ContactDetector`` = sim_rig + tactile_sensor + arm_commander), so a seed and
a config give the same touch sequence offline and on the graph.

World frame, metres, seconds. Travel and time follow
:class:`tactile_bringup.motion.MotionModel`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from tactile_common.fields import LABEL_CONTACT, LABEL_FREE_SPACE
from tactile_gpis import estimator as gpis_estimator
from tactile_gpis.estimator import ShapeEstimator
from tactile_planner import planner as soc_planner
from tactile_planner.planner import TouchPlanner
from tactile_sim import metrics
from tactile_sim.objects import SDFObject, make_object

from .experiment import Experiment
from .motion import MotionModel, polyline_length_m
from .report import make_report
from .sensing import SimulatedFinger

ProgressFn = Callable[[dict], None]


@dataclass
class LoopState:
    """What the loop carries from one touch to the next."""

    tip_xyz: np.ndarray
    travel_m: float = 0.0
    time_s: float = 0.0
    excluded: list = field(default_factory=list)
    touches: list = field(default_factory=list)


class ExplorationLoop:
    """One exploration run of one object with one strategy and seed."""

    def __init__(self, experiment: Experiment) -> None:
        self.exp = experiment
        self.obj: SDFObject = make_object(
            experiment.object_name, mode=experiment.mode, **experiment.object_pose_kwargs()
        )
        # A node ignores the parameters of a file that it does not declare; so do we.
        self.estimator = ShapeEstimator.from_params(
            _declared(experiment.gpis_params, gpis_estimator.PARAMETERS))
        self.planner = TouchPlanner.from_params(
            _declared(experiment.planner_params, soc_planner.PARAMETERS), seed=experiment.seed)
        self.finger = SimulatedFinger.from_params(experiment, self.obj)
        self.motion = MotionModel.from_params(experiment.planner_params)
        self.eval_points = metrics.evaluation_lattice(
            experiment.evaluation_bounds(), experiment.evaluation_resolution_m
        )
        self.true_surface = metrics.true_surface_samples(self.obj)

    # -- metrics -------------------------------------------------------------
    def _dims(self, points_xyz: np.ndarray) -> np.ndarray:
        return points_xyz[:, : self.obj.dim]

    def iou(self) -> float:
        est = self.estimator
        return metrics.iou(lambda p: est.inside(p), self.obj, self.eval_points)

    def surface_error_m(self) -> Optional[float]:
        surf = self.estimator.surface_points()
        if len(surf) == 0:
            return None
        return metrics.surface_error(self.obj, self._dims(surf))

    # -- the loop ------------------------------------------------------------
    def run(self, progress: Optional[ProgressFn] = None) -> dict:
        exp = self.exp
        state = LoopState(tip_xyz=np.asarray(exp.start_tip_xyz, dtype=float))
        prior_iou = self.iou()
        stopped = "touch budget"
        for index in range(exp.touches):
            if exp.max_travel_m and state.travel_m >= exp.max_travel_m:
                stopped = "travel budget"
                break
            t0 = time.perf_counter()
            plan = self.planner.plan(
                self.estimator.map_array(), state.tip_xyz,
                np.asarray(state.excluded, dtype=float).reshape(-1, 3),
            )
            plan_ms = (time.perf_counter() - t0) * 1e3  # map extraction + planning
            if not plan.ok:
                stopped = f"planner: {plan.status}: {plan.message}"
                break
            record = self._touch(index, plan, state)
            record["decision_ms"] += plan_ms
            state.touches.append(record)
            if progress is not None:
                progress(record)
            if exp.confidence_max_var_m2 and record["max_surface_var_m2"] is not None \
                    and record["max_surface_var_m2"] < exp.confidence_max_var_m2:
                stopped = "confidence"
                break
        return make_report(
            exp.object_name, exp.mode, exp.strategy, exp.seed, exp.config_summary(),
            state.touches, prior_iou, stopped,
        )

    def _touch(self, index: int, plan, state: LoopState) -> dict:
        """Execute one planned touch; update the estimate; the touch record."""
        path = np.vstack([state.tip_xyz[None, :], plan.path_xyz])
        path_m = polyline_length_m(path)
        approach_dir = -np.asarray(plan.normal_xyz, dtype=float)
        result = self.finger.approach(plan.pretouch_xyz, approach_dir, index)
        approach_m = result.travel_m
        state.travel_m += path_m + 2.0 * approach_m
        state.time_s += self.motion.touch_time_s(path_m, approach_m)
        state.tip_xyz = np.asarray(plan.pretouch_xyz, dtype=float)

        t_update = time.perf_counter()
        if result.contact:
            self.estimator.add_observation(result.point_xyz, result.normal_xyz, LABEL_CONTACT)
        else:
            self.estimator.add_observation(result.tip_xyz_at_stop, None, LABEL_FREE_SPACE)
        update_ms = (time.perf_counter() - t_update) * 1e3
        _, var = self.estimator.predict(np.asarray(plan.target_xyz, dtype=float)[None, :])
        surf = self.estimator.map_array()
        cand = surf[surf["kind"] == 1]
        return {
            "index": index,
            "target": _round(plan.target_xyz),
            "contact": _round(result.point_xyz) if result.contact else None,
            "normal": _round(result.normal_xyz) if result.contact else None,
            "outcome": "contact" if result.contact else "free_space",
            "travel_m": state.travel_m,
            "time_s": state.time_s,
            "iou": self.iou(),
            "surface_error_m": self.surface_error_m(),
            "decision_ms": update_ms,
            "target_var_after_m2": float(var[0]),
            "max_surface_var_m2": float(cand["variance"].max()) if len(cand) else None,
        }


def _declared(params: dict, table: dict) -> dict:
    return {k: v for k, v in params.items() if k in table}


def _round(v: Sequence[float]) -> list:
    return [round(float(x), 7) for x in np.asarray(v).ravel()]


def run_exploration(experiment: Experiment, progress: Optional[ProgressFn] = None) -> dict:
    """Run one exploration and return its report (see :mod:`tactile_bringup.report`)."""
    return ExplorationLoop(experiment).run(progress)
