"""One slide touch of the offline loop: approach, slide, back off (ROS-free).

World frame, metres, seconds. With touch ``slide`` the loop runs, for a plan
(pre-touch point, approach direction −n, slide direction and length):

- the free-space path; a path that meets the object slides on from that
  contact (the plan's direction projected on the sensed tangent);
- otherwise a guarded approach from the pre-touch point for ``standoff_m +
  approach_depth_m`` (the servo's ``approach_depth_m``, deeper than a poke's
  ``max_depth_m``: a slide's first contact is worth a longer search); no
  contact: a free-space observation, and the finger stays at the probe end
  (it is in free space: nothing to retract from);
- a contact: the slide (:meth:`SimulatedFinger.slide`; after an approach, on
  the plan's normal until a contact has one), then the back-off from its last
  contact.

Travel = path + approach + slide (tip path) + back-off. Time
(:meth:`MotionModel.slide_time_s`): path at tip speed, approach and back-off
at approach speed, dwell, and the slide's ticks at the control rate.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from tactile_common.touch_geometry import MotionModel, polyline_length_m
from tactile_sim.slide import SlideResult
from tactile_sim.touch import ApproachResult


@dataclass(frozen=True)
class SlideTouch:
    """The outcome: the approach (or path contact), the slide (None without contact), the tip after
    the touch, this touch's travel and time, and the followed part of the path (None: all of it)."""

    approach: ApproachResult
    slide: Optional[SlideResult]
    tip_xyz: np.ndarray
    travel_m: float
    time_s: float
    path_followed_m: Optional[float]
    #: travel and time within this touch when the slide's contact k was sensed (K,), (K,)
    contact_travel_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))


def slide_touch(finger, motion: MotionModel, plan, path_xyz: np.ndarray, hit, touch_index: int,
                standoff_m: float) -> SlideTouch:
    """Run one slide touch (module docstring); ``hit`` is ``finger.path_contact(path)``."""
    direction = np.asarray(plan.slide_direction_xyz, dtype=float)
    length = float(plan.slide_length_m)
    if hit is not None:
        free_m, result, _ = hit
        slide, tip = finger.slide(result, direction, length, touch_index)
        back_m = float(np.linalg.norm(tip - slide.tip_path_xyz[-1]))
        moved_m = free_m + result.travel_m
        # the path up to the contact runs at tip speed (as a poke's path contact), then slide and back-off
        time_s = motion.slide_time_s(moved_m, 0.0, slide.duration_s * motion.slide_speed_mps, back_m)
        lead_m, lead_s = moved_m, moved_m / motion.tip_speed_mps + motion.dwell_s
        return SlideTouch(result, slide, tip, moved_m + slide.travel_m + back_m, float(time_s), free_m,
                          *_along(slide, lead_m, lead_s, motion))
    path_m = polyline_length_m(path_xyz)
    depth_m = standoff_m + finger.servo.approach_depth_m
    result = finger.approach(plan.pretouch_xyz, -np.asarray(plan.normal_xyz), touch_index, max_travel_m=depth_m)
    if not result.contact:
        time_s = motion.slide_time_s(path_m, result.travel_m, 0.0, 0.0)
        return SlideTouch(result, None, np.asarray(result.tip_xyz_at_stop, dtype=float),
                          path_m + result.travel_m, float(time_s), None)
    slide, tip = finger.slide(result, direction, length, touch_index, normal_xyz=plan.normal_xyz)
    back_m = float(np.linalg.norm(tip - slide.tip_path_xyz[-1]))
    time_s = motion.slide_time_s(path_m, result.travel_m, slide.duration_s * motion.slide_speed_mps, back_m)
    lead_m = path_m + result.travel_m
    lead_s = path_m / motion.tip_speed_mps + result.travel_m / motion.approach_speed_mps + motion.dwell_s
    return SlideTouch(result, slide, tip, path_m + result.travel_m + slide.travel_m + back_m, float(time_s), None,
                      *_along(slide, lead_m, lead_s, motion))


def _along(slide: SlideResult, lead_m: float, lead_s: float, motion: MotionModel) -> tuple[np.ndarray, np.ndarray]:
    """Travel and time within the touch at each contact of the slide: the lead (path, approach,
    dwell) plus the tip path up to the contact's tick, and its ticks at the control rate."""
    seg = np.linalg.norm(np.diff(slide.tip_path_xyz, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    k = np.asarray(slide.point_ticks, dtype=int)
    per_tick_s = slide.duration_s / max(len(slide.tip_path_xyz) - 1, 1)
    return lead_m + cum[k], lead_s + k * per_tick_s


def observe_stream(estimator, evaluator, st: SlideTouch, travel_before_m: float, time_before_s: float,
                   every: int = 4, known_mean_m: float = 0.0005, known_sd_m: float = 0.0008,
                   ) -> tuple[list[dict], int, float]:
    """Feed the slide's contacts to the estimator in the order sensed (as the driver streams them) and,
    every ``every`` contacts, a checkpoint of the estimate: ``{"travel_m", "time_s", "iou",
    "iou_reachable", "contacts"}`` with the run's cumulative travel and time at that contact.

    Thinning by variance: a contact the estimate already predicts (|μ(p)| < ``known_mean_m`` and
    σ(p) < ``known_sd_m``, predicted before its chunk is added) is skipped: a second lap over a
    known surface adds nothing but cost. The estimator takes a chunk through ``add_observations``
    when it has one, else one ``add_observation`` each. Returns (checkpoints, contacts added, seconds
    spent on the checkpoints): the checkpoints measure the estimate against the true object, which only a
    simulation has, so a touch's decision time leaves them out.
    """
    from tactile_common.fields import LABEL_CONTACT

    slide = st.slide
    out: list[dict] = []
    if slide is None or slide.n_contacts == 0:
        return out, 0, 0.0
    batch = getattr(estimator, "add_observations", None)
    K, used, checkpoint_s = slide.n_contacts, 0, 0.0
    normals = slide.normals_xyz
    for lo in range(0, K, every):
        hi = min(K, lo + every)
        mu, var = estimator.predict(slide.points_xyz[lo:hi])
        keep = lo + np.nonzero(~((np.abs(mu) < known_mean_m) & (np.sqrt(np.maximum(var, 0.0)) < known_sd_m)))[0]
        used += len(keep)
        if len(keep) and batch is not None:
            batch(slide.points_xyz[keep], normals[keep], np.full(len(keep), LABEL_CONTACT))
        else:
            for k in keep:
                estimator.add_observation(slide.points_xyz[k], normals[k], LABEL_CONTACT)
        if evaluator is not None and hi < K and len(keep):  # the touch's own record covers the last one
            t0 = time.perf_counter()
            out.append({"travel_m": float(travel_before_m + st.contact_travel_m[hi - 1]),
                        "time_s": float(time_before_s + st.contact_time_s[hi - 1]),
                        "iou": evaluator.iou(estimator), "iou_reachable": evaluator.iou_reachable(estimator),
                        "contacts": hi})
            checkpoint_s += time.perf_counter() - t0
    return out, used, checkpoint_s

