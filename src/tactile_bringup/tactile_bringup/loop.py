"""The exploration loop, ROS-free: the node graph's touch cycle run in one process.

estimate → candidates → plan → move along the path → guarded approach along
−normal until the finger's surface meets the object (contact) or a maximum
depth (free space) → retract → update; a path that meets the object stops on
that contact and backs off (the arm commander's behaviour). It uses the same
cores with the same parameters as the nodes (``ShapeEstimator`` =
gpis_estimator, ``TouchPlanner`` = soc_planner, ``simulate_approach`` with the
driver's ``ContactDetector`` = sim_rig + tactile_sensor + arm_commander). A
seed and a config give the same touch sequence on every offline run; how far
a graph run follows it: docs/exploration.md, "Determinism".

World frame, metres, seconds. Travel and time follow
:class:`tactile_bringup.motion.MotionModel`.
"""

from __future__ import annotations

import time
from typing import Callable, Optional

import numpy as np

from .cores import make_estimator, make_planner
from .evaluation import Evaluator
from .experiment import Experiment
from .motion import MotionModel, polyline_length_m
from .progress import observe, stop_reason, touch_record
from .report import make_report
from .sensing import SimulatedFinger
from .slide_touch import observe_stream, slide_touch

ProgressFn = Callable[[dict], None]


class ExplorationLoop:
    """One exploration run of one object with one strategy and seed."""

    def __init__(self, experiment: Experiment) -> None:
        self.exp = experiment
        self.evaluator = Evaluator(experiment)
        self.estimator = make_estimator(experiment)
        self.planner = make_planner(experiment)
        self.finger = SimulatedFinger.from_params(experiment, self.evaluator.obj)
        self.motion = MotionModel.from_params(experiment.planner_params)
        self.touch = str(experiment.planner_params.get("touch", "poke"))  # 'poke' | 'slide' (the planner's too)
        self.standoff_m = float(experiment.planner_params.get("standoff_m", 0.01))

    @property
    def true_surface(self) -> np.ndarray:
        return self.evaluator.true_surface

    def run(self, progress: Optional[ProgressFn] = None) -> dict:
        exp = self.exp
        tip = np.asarray(exp.start_tip_xyz, dtype=float)
        travel_m = time_s = 0.0
        touches: list[dict] = []
        prior_iou = self.evaluator.iou(self.estimator)
        stopped = "touch budget" if exp.touches > 0 else "no touches asked"
        while stop_reason(exp, touches) is None:
            t0 = time.perf_counter()
            plan = self.planner.plan(self.estimator.map_array(), tip, np.zeros((0, 3)))
            plan_ms = (time.perf_counter() - t0) * 1e3  # map extraction + planning
            if not plan.ok:
                stopped = f"planner: {plan.status}: {plan.message}"
                break
            # Move from the tip along the path, approach along −normal, retract. A path that
            # meets the object (the estimate was too small there) stops on the contact and
            # backs off from it, as the arm commander does.
            path = np.vstack([tip[None, :], plan.path_xyz])
            hit = self.finger.path_contact(path, len(touches))
            slide = None
            if self.touch == "slide" and np.isfinite(plan.slide_length_m):
                # Approach (or the path's contact), slide along the surface, back off (slide_touch).
                st = slide_touch(self.finger, self.motion, plan, path, hit, len(touches), self.standoff_m)
                result, slide, tip = st.approach, st.slide, st.tip_xyz
                travel_m += st.travel_m
                time_s += st.time_s
                free_m = st.path_followed_m
                hit = None if free_m is None else hit
            elif hit is None:
                path_m = polyline_length_m(path)
                result = self.finger.approach(plan.pretouch_xyz, -np.asarray(plan.normal_xyz), len(touches))
                travel_m += path_m + 2.0 * result.travel_m
                time_s += self.motion.touch_time_s(path_m, result.travel_m)
                tip = np.asarray(plan.pretouch_xyz, dtype=float)
            else:
                free_m, result, tip = hit
                back_m = float(np.linalg.norm(tip - result.tip_xyz_at_stop))
                travel_m += free_m + result.travel_m + back_m
                time_s += self.motion.path_contact_time_s(free_m + result.travel_m, back_m)
            t1 = time.perf_counter()
            point = result.point_xyz if result.contact else result.tip_xyz_at_stop
            # a miss: the guarded approach swept free space from the pre-touch point to the probe end
            sweep = None if result.contact else np.asarray(plan.pretouch_xyz, dtype=float) - point
            observe(self.estimator, point, result.normal_xyz if result.contact else sweep, result.contact)
            stream, used = None, None
            if slide is not None:  # the slide's thinned contact stream, in the order sensed, with checkpoints
                stream, used = observe_stream(self.estimator, self.evaluator, st, travel_m - st.travel_m,
                                              time_s - st.time_s)
                point, normal = (slide.points_xyz[-1], slide.normals_xyz[-1]) if slide.n_contacts else \
                    (point, result.normal_xyz)
            else:
                normal = result.normal_xyz
            update_ms = (time.perf_counter() - t1) * 1e3
            record = touch_record(len(touches), plan.target_xyz, result.contact, point, normal,
                                  travel_m, time_s, plan_ms + update_ms, self.estimator, self.evaluator,
                                  path_xyz=path, path_followed_m=None if hit is None else free_m, slide=slide,
                                  stream=stream, contacts_used=used)
            touches.append(record)
            if progress is not None:
                progress(record)
            stopped = stop_reason(exp, touches) or stopped
        return make_report(exp.object_name, exp.mode, exp.strategy, exp.seed, exp.config_summary(),
                           touches, prior_iou, stopped)


def run_exploration(experiment: Experiment, progress: Optional[ProgressFn] = None) -> dict:
    """Run one exploration and return its report (see :mod:`tactile_bringup.report`)."""
    return ExplorationLoop(experiment).run(progress)
