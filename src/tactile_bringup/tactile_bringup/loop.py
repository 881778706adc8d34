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

from tactile_common.finger_axis import EZ

from .cores import make_estimator, make_planner
from .evaluation import Evaluator
from .exploration_cycle import CycleConfig
from .experiment import Experiment
from .motion import MotionModel, polyline_length_m
from .progress import misses_before_contact, observe, stop_reason, touch_record
from .report import make_report
from .rig_touch import RigError, RigFinger
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
        self.finger = SimulatedFinger.from_params(experiment, self.evaluator.obj)  # slides
        self.motion = MotionModel.from_params(experiment.planner_params)
        self.touch = str(experiment.planner_params.get("touch", "poke"))  # 'poke' | 'slide' (the planner's too)
        # Pokes: the graph's rig, driver and commander plans in this process (rig_touch), so a seed gives
        # the graph's touch sequence. A slide run pokes (rarely) with the model finger: the graph's slides
        # are not replayed here, so the rig's joints would not be the graph's after one.
        self.poker = RigFinger(experiment, self.evaluator.obj) if self.touch == "poke" else self.finger
        explorer = experiment.node_params("explorer")
        self.max_unreachable = int(explorer.get("max_unreachable", CycleConfig.max_unreachable))  # as the explorer
        self.max_retries = int(explorer.get("max_retries", CycleConfig.max_retries))
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
        excluded: list[np.ndarray] = []  # targets reported unreachable (the planner node's exclusion)
        unreachable_in_row = aborts_in_row = 0
        while stop_reason(exp, touches) is None:
            t0 = time.perf_counter()
            plan = self.planner.plan(self.estimator.map_array(), tip, np.array(excluded).reshape(-1, 3),
                                     misses_before_contact=misses_before_contact(touches))
            plan_ms = (time.perf_counter() - t0) * 1e3  # map extraction + planning
            if not plan.ok:
                stopped = f"planner: {plan.status}: {plan.message}"
                break
            path = np.vstack([tip[None, :], plan.path_xyz])
            slide = None
            if self.touch == "slide" and np.isfinite(plan.slide_length_m):
                # Approach (or the path's contact), slide along the surface, back off (slide_touch).
                hit = self.finger.path_contact(path, len(touches))
                st = slide_touch(self.finger, self.motion, plan, path, hit, len(touches), self.standoff_m)
                result, slide, tip = st.approach, st.slide, st.tip_xyz
                travel_m += st.travel_m
                time_s += st.time_s
                followed_m = st.path_followed_m if hit is not None else None  # a path contact: how far
                contact = result.contact
                point = result.point_xyz if contact else result.tip_xyz_at_stop
                # a miss: the guarded approach swept free space from the pre-touch point to the probe end
                sweep = None if contact else np.asarray(plan.pretouch_xyz, dtype=float) - point
                normal = result.normal_xyz
            else:
                # Move along the path, approach along the goal's axis, retract; a path that meets the
                # object stops on the contact and backs off from it (the arm commander's touch).
                try:
                    poke = self.poker.poke(plan, tip, len(touches))
                except RigError as exc:
                    stopped = f"rig: {exc}"
                    break
                if poke.outcome == "unreachable":  # nothing moved: plan again without that target
                    excluded.append(np.asarray(plan.target_xyz, dtype=float))
                    unreachable_in_row += 1
                    if unreachable_in_row >= self.max_unreachable:
                        stopped = f"{unreachable_in_row} unreachable goals in a row"
                        break
                    continue
                if poke.outcome == "aborted":  # moved along the path, refused the approach: the explorer's retry
                    path_m = polyline_length_m(path)
                    travel_m += path_m
                    time_s += self.motion.path_contact_time_s(path_m, 0.0)
                    tip = np.asarray(poke.end_xyz, dtype=float)
                    aborts_in_row += 1
                    if aborts_in_row > self.max_retries:
                        stopped = f"touch aborted: {poke.reason}; gave up after {self.max_retries} retries"
                        break
                    continue
                unreachable_in_row = aborts_in_row = 0
                contact, point, normal, sweep, tip = poke.contact, poke.point_xyz, poke.normal_xyz, poke.sweep_xyz, \
                    np.asarray(poke.end_xyz, dtype=float)
                free_m = followed_m = poke.path_followed_m
                if free_m is None:
                    path_m = polyline_length_m(path)
                    travel_m += path_m + 2.0 * poke.approach_m
                    time_s += self.motion.touch_time_s(path_m, poke.approach_m)
                else:
                    travel_m += free_m + poke.approach_m + poke.back_off_m
                    time_s += self.motion.path_contact_time_s(free_m + poke.approach_m, poke.back_off_m)
                if poke.untilt_m or poke.untilt_s:  # a tilted finger's way back, and its turn on the way in:
                    travel_m += poke.untilt_m  # the path counted the insertion at tip speed; each way takes
                    time_s += 2.0 * poke.untilt_s - poke.untilt_m / self.motion.tip_speed_mps  # the planned time
            t1 = time.perf_counter()
            observe(self.estimator, point, normal if contact else sweep, contact)
            stream, used, checkpoint_s = None, None, 0.0
            if slide is not None:  # the slide's thinned contact stream, in the order sensed, with checkpoints
                stream, used, checkpoint_s = observe_stream(self.estimator, self.evaluator, st,
                                                            travel_m - st.travel_m, time_s - st.time_s)
                point, normal = (slide.points_xyz[-1], slide.normals_xyz[-1]) if slide.n_contacts else \
                    (point, normal)
            update_ms = (time.perf_counter() - t1 - checkpoint_s) * 1e3  # the estimator's, not the evaluation's
            record = touch_record(len(touches), plan.target_xyz, contact, point, normal,
                                  travel_m, time_s, plan_ms + update_ms, self.estimator, self.evaluator,
                                  path_xyz=path, path_followed_m=followed_m, slide=slide,
                                  stream=stream, contacts_used=used, path_axes_xyz=_with_start(plan.path_axes_xyz))
            touches.append(record)
            if progress is not None:
                progress(record)
            stopped = stop_reason(exp, touches) or stopped
        return make_report(exp.object_name, exp.mode, exp.strategy, exp.seed, exp.config_summary(),
                           touches, prior_iou, stopped, travel_m, time_s)


def run_exploration(experiment: Experiment, progress: Optional[ProgressFn] = None) -> dict:
    """Run one exploration and return its report (see :mod:`tactile_bringup.report`)."""
    return ExplorationLoop(experiment).run(progress)


def _with_start(axes_xyz: np.ndarray) -> Optional[np.ndarray]:
    """The finger axes of a touch's path with the tip's start prepended (vertical: between touches the
    finger is); None for a vertical finger's path."""
    axes = np.asarray(axes_xyz, dtype=float).reshape(-1, 3)
    return np.vstack([EZ, axes]) if len(axes) else None
