"""One touch as a state machine over the :class:`ArmCommander` verbs (docs/architecture.md, touch cycle).

    validate -> follow_path -> approach -> (contact | free space) -> dwell -> retract -> done

Validation plans the whole touch first (path, then the approach from the
path's end configuration; box + IK): an infeasible touch is reported as
``unreachable`` and nothing moves. An approach that reaches its depth
without contact publishes the free-space point (tip centre, label 0).
A contact on the path (the map said free space there) is an observation
like any other: the arm stops, backs off the surface (``back_off``) and the
touch ends as ``contact`` (reason ``path: unexpected contact ...``).
An approach the commander stopped because the sensor fell silent
(``sensor_lost``: the finger must not press on blind) waits until the driver
has judged the frames up to the stop, retracts to where the approach began
(joint space: the same joints every time) and approaches again, at most
``SENSOR_RETRIES`` times; the redo is the same motion, so the touch observes
what it would have without the outage. Any other abort (e-stop, stale joint
states, time-out) ends the touch as ``aborted``. In dry-run mode the three motions are planned and published
for inspection only and the touch ends as ``aborted`` (reason ``dry_run``).
A tilted touch (``TouchRequest.tail``, tactile_common.finger_axis) plans its path with the finger
axes, and whatever its outcome (not ``unreachable``, not under the e-stop) ends with ``untilt``: back
through the path's own planned joints to its last vertical waypoint, the entry point
(:meth:`ArmCommander.retrace`), so that every touch ends with the finger vertical.
No message handling here: the node passes the commander and two publish callbacks.

A slide request (``slide_length_m`` set; tactile_common.slide_goal):

    validate -> follow_path -> approach (standoff + servo.approach_depth_m) -> contact -> slide -> back_off -> done
                            (path contact) -> slide ...      approach at full depth -> free space -> done

The slide (:meth:`ArmCommander.slide`) starts where the approach's contact
stopped the arm, or where the path met the object; then the arm backs off
``back_off_clearance_m`` from the slide's last contact (the touch's nominal
end). Free space after the approach: the finger stays at the probe end (it
is in free space: nothing to retract from). The report carries the slid
length, why it stopped, and the contact stream: the approach's contact
(``first_observation_stamp_ns``) to the last one published
(``observation_stamp_ns``), ``contacts`` in all. As offline
(tactile_bringup.slide_touch).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from tactile_common import fields
from tactile_common.cycle import TouchOutcome, TouchReport
from tactile_common.finger_axis import TiltedTail
from tactile_driver.arm_motions import turn_start_index
from tactile_driver.commander_api import ArmCommander, TaskResult
from tactile_driver.safety import OutsideWorkspace
from tactile_driver.trajectory import TrajectoryError

OUTCOME_CONTACT = TouchOutcome.CONTACT
OUTCOME_FREE_SPACE = TouchOutcome.FREE_SPACE
OUTCOME_UNREACHABLE = TouchOutcome.UNREACHABLE
OUTCOME_ABORTED = TouchOutcome.ABORTED

#: Approaches stopped for a silent sensor that are retried within one touch.
SENSOR_RETRIES = 2


@dataclass
class TouchRequest:
    goal_stamp_ns: int
    pre_touch_xyz: np.ndarray  # world, m
    approach_dir: np.ndarray  # unit, world (the goal's x-axis)
    path_xyz: np.ndarray  # (K, 3) world, m
    slide_direction_xyz: Optional[np.ndarray] = None  # a slide: unit start direction (world)
    slide_length_m: float = float("nan")  # a slide: planned length (m); NaN: a poke
    path_axes_xyz: Optional[np.ndarray] = None  # (K, 3) finger axis at each path point; None: vertical
    tail: Optional[TiltedTail] = None  # a tilted touch: where the finger turns, its axis (tactile_common.finger_axis)

    @property
    def is_slide(self) -> bool:
        return self.slide_direction_xyz is not None and bool(np.isfinite(self.slide_length_m))


class TouchExecutor:
    """Runs queued touches one after the other; call :meth:`update` periodically."""

    def __init__(self, arm: ArmCommander, approach_length_m: float, dwell_s: float,
                 publish_free_space: Callable[[np.ndarray, int, np.ndarray], None],
                 publish_done: Callable[[TouchReport], None], back_off_clearance_m: float = 0.01,
                 slide_servo=None, slide_approach_length_m: Optional[float] = None,
                 min_approach_m: float = 0.0) -> None:
        if approach_length_m <= 0:
            raise ValueError("approach length (standoff + max depth) must be positive")
        #: An approach the safety box shortens below this (TouchGeometry.min_approach_m: it could not
        #: test the estimated surface) makes the touch unreachable.
        self.min_approach_m = float(min_approach_m)
        self.slide_servo = slide_servo  # SlideServoConfig; None: slides are refused (unreachable)
        self.slide_approach_length_m = float(slide_approach_length_m or approach_length_m)
        self.arm = arm
        self.approach_length_m = float(approach_length_m)
        self.dwell_s = float(dwell_s)
        self.back_off_clearance_m = float(back_off_clearance_m)
        self._publish_free_space = publish_free_space
        self._publish_done = publish_done
        self.queue: deque[TouchRequest] = deque()
        self.hold = False  # True: queue touches but do not start them (e.g. moving to the start)
        self._req: Optional[TouchRequest] = None
        self._state = "idle"
        self._t0_s = 0.0
        self._odo0_m = 0.0
        self._dwell_until_s = 0.0
        self._outcome = ""
        self._reason = ""
        self._obs_stamp_ns: Optional[int] = None
        self._travel_planned_m = 0.0
        self._end_xyz: Optional[np.ndarray] = None
        self._first_obs_ns: Optional[int] = None
        self._slide: Optional[dict] = None  # the slide's outcome (task extra)
        self._path_traj = None  # the plan of the touch's path (a tilted finger's way back)

    @property
    def busy(self) -> bool:
        return self._req is not None

    def submit(self, request: TouchRequest) -> None:
        self.queue.append(request)
        self.update()

    def update(self) -> None:
        if self._req is None:
            if self.queue and not self.hold:
                self._begin(self.queue.popleft())
            return
        arm = self.arm
        if not arm.is_task_complete():
            return
        result, task = arm.get_result(), arm.last_task
        slide = self._req.is_slide
        if self._state == "path":
            self._path_traj = task.traj  # a tilted finger goes back through its waypoints
            if result == TaskResult.ABORTED and task.contact is not None and not arm.estop.engaged:
                if slide:  # the path met the object: slide on from that contact
                    self._reason = f"path: {task.reason}"
                    return self._start_slide(task.contact_stamp_ns, from_approach=False)
                return self._back_off(task)
            if result != TaskResult.SUCCEEDED:
                return self._done(OUTCOME_ABORTED, f"path: {task.reason}")
            self._travel_planned_m += task.traj.length_m
            return self._start_approach()
        elif self._state == "slide":
            self._slide = dict(task.extra)
            if result != TaskResult.SUCCEEDED:
                return self._done(OUTCOME_ABORTED, f"slide: {task.reason}")
            self._outcome = OUTCOME_CONTACT
            self._reason = "; ".join(filter(None, [self._reason, task.reason]))
            last = self._slide.get("last_contact")
            if last is not None:
                self._obs_stamp_ns = int(round(last.stamp_s * 1e9))
                contact_xyz = np.asarray(last.sense.point_xyz, dtype=float)
            else:
                contact_xyz = self._onset_xyz
            if not arm.back_off(contact_xyz, self.back_off_clearance_m):
                return self._done(OUTCOME_ABORTED, f"slide: back_off: {arm.last_task.reason}")
            self._end_xyz = np.asarray(arm.back_off_xyz, dtype=float)
            self._state = "retract"
        elif self._state == "sensor_wait":
            waited_s = arm.now_s() - self._sensor_stop_s
            back = arm.sensor_decided_s >= self._sensor_stop_s
            if not back and waited_s < arm.cfg.sensor_confirm_timeout_s:
                return
            if not arm.retract():
                return self._done(OUTCOME_ABORTED, f"approach: sensor silent; retract: {arm.last_task.reason}")
            self._state = "sensor_retract" if back else "sensor_gone"
        elif self._state in ("sensor_retract", "sensor_gone"):
            if result != TaskResult.SUCCEEDED:
                return self._done(OUTCOME_ABORTED, f"approach: sensor silent; retract: {task.reason}")
            if self._state == "sensor_gone":
                return self._done(OUTCOME_ABORTED, f"approach: the sensor driver was silent for more than "
                                                   f"{arm.cfg.sensor_confirm_timeout_s:g} s (retracted)")
            return self._start_approach(self.arm.approach_origin_q)  # the same approach again, from the same joints
        elif self._state == "approach":
            self._travel_planned_m += task.traj.length_m
            if (result == TaskResult.ABORTED and getattr(task, "sensor_lost", False) and not arm.estop.engaged
                    and self._sensor_retries < SENSOR_RETRIES):
                self._sensor_retries += 1
                self._sensor_stop_s = arm.now_s()
                self._reason = "; ".join(filter(None, [self._reason, f"approach stopped ({task.reason}), "
                                                                     "retracted and repeated"]))
                self._state = "sensor_wait"
                return self.update()
            if slide and result == TaskResult.CONTACT and not arm.cfg.dry_run:
                return self._start_slide(task.contact_stamp_ns, task.contact)
            if arm.cfg.dry_run:
                self._outcome = OUTCOME_ABORTED
            elif result == TaskResult.CONTACT:
                self._outcome, self._obs_stamp_ns = OUTCOME_CONTACT, task.contact_stamp_ns
            elif result == TaskResult.SUCCEEDED:
                stamp_ns = int(round(arm.now_s() * 1e9))
                # The probe end: FK of the final commanded joints (the arm is there within goal tolerance),
                # and the sweep back to the approach's first point (free space all along it).
                end = arm.model.fk(task.traj.positions_rad[-1])[0]
                self._publish_free_space(end, stamp_ns, arm.model.fk(task.traj.positions_rad[0])[0] - end)
                self._outcome, self._obs_stamp_ns = OUTCOME_FREE_SPACE, stamp_ns
                if slide:  # in free space: nothing to retract from; the finger stays at the probe end
                    self._end_xyz = arm.model.fk(task.traj.positions_rad[-1])[0]
                    return self._done(self._outcome, "slide: no contact within the approach")
            else:
                return self._done(OUTCOME_ABORTED, f"approach: {task.reason}")
            self._dwell_until_s = arm.now_s() + (0.0 if arm.cfg.dry_run else self.dwell_s)
            self._dwelt_s = 0.0 if arm.cfg.dry_run else self.dwell_s
            self._state = "dwell"
        elif self._state == "dwell":
            if arm.now_s() < self._dwell_until_s:
                return
            if arm.estop.engaged:
                return self._done(OUTCOME_ABORTED, "e-stop")
            if not arm.retract():
                return self._done(OUTCOME_ABORTED, f"retract: {arm.last_task.reason}")
            self._state = "retract"
        elif self._state == "untilt":
            outcome, reason = self._untilt_then
            if result != TaskResult.SUCCEEDED:
                return self._finish(OUTCOME_ABORTED, "; ".join(filter(None, [
                    reason, f"turning the finger back to vertical: {task.reason}"])))
            self._travel_planned_m += task.traj.length_m
            self._end_xyz = np.asarray(self._req.tail.entry_xyz, dtype=float)  # the next touch starts there
            return self._finish(outcome, reason)
        elif self._state == "retract":
            if result != TaskResult.SUCCEEDED:
                return self._done(OUTCOME_ABORTED, f"retract: {task.reason}")
            self._travel_planned_m += task.traj.length_m
            # Nominal end: the pre-touch point after a retract, the back-off point after a path contact
            # (the next touch is planned from there, offline as on the graph).
            self._end_xyz = self._req.pre_touch_xyz if self._end_xyz is None else self._end_xyz
            self._done(self._outcome, "dry_run: planned, not executed" if arm.cfg.dry_run else self._reason)

    def _begin(self, req: TouchRequest) -> None:
        self._req, self._t0_s, self._odo0_m = req, self.arm.motion_time_s, self.arm.odometer_m
        self._obs_stamp_ns, self._outcome, self._reason, self._travel_planned_m = None, "", "", 0.0
        self._end_xyz = self._path_traj = None
        self._first_obs_ns, self._slide, self._onset_xyz = None, None, None
        self._dwelt_s = 0.0  # robot time of the dwell (not a motion)
        self._sensor_retries, self._sensor_stop_s = 0, 0.0
        if req.is_slide and (self.slide_servo is None or self.arm.cfg.dry_run):
            return self._done(OUTCOME_UNREACHABLE, "slide goal: this commander does not slide"
                              + (" in dry run" if self.arm.cfg.dry_run else ""))
        depth = self.slide_approach_length_m if req.is_slide else self.approach_length_m
        path = np.vstack([req.path_xyz.reshape(-1, 3), req.pre_touch_xyz[None]])
        axes = None if req.path_axes_xyz is None else np.vstack([req.path_axes_xyz, req.path_axes_xyz[-1:]])
        try:  # plan the whole touch before moving (an approach too short to reach the surface: unreachable)
            to_goal = self.arm.plan(path, axes_xyz=axes)
            depth = self.arm.approach_depth_m(req.pre_touch_xyz, req.approach_dir, depth,
                                              min(self.min_approach_m, depth))
            self.arm.plan(req.pre_touch_xyz + depth * req.approach_dir,
                          q_start=to_goal.positions_rad[-1], speed_mps=self.arm.cfg.approach_speed_mps,
                          step_m=self.arm.cfg.approach_step_m)
        except (OutsideWorkspace, TrajectoryError) as exc:
            return self._done(OUTCOME_UNREACHABLE, str(exc))
        if not self.arm.follow_path(path, axes):
            return self._done(OUTCOME_ABORTED, f"path: {self.arm.last_task.reason}")
        self._state = "path"

    def _start_approach(self, q_start: Optional[np.ndarray] = None) -> None:
        """The guarded approach from the pre-touch point along the goal's axis (a slide's: its own depth);
        ``q_start``: planned from these joints (a repeat: where the retract took the arm back to)."""
        depth = self.slide_approach_length_m if self._req.is_slide else self.approach_length_m
        if not self.arm.approach(self._req.approach_dir, depth, q_start=q_start):
            return self._done(OUTCOME_ABORTED, f"approach: {self.arm.last_task.reason}")
        self._state = "approach"

    def _start_slide(self, contact_stamp_ns: int, contact=None, from_approach: bool = True) -> None:
        """The approach (or the path) met the surface: slide from here (after an approach, on its
        reversed direction until the driver senses a normal: a contact on the finger's rim has none)."""
        task = self.arm.last_task
        self._first_obs_ns = int(contact_stamp_ns)
        record = contact if contact is not None else task.contact
        self._onset_xyz = fields.xyz(np.atleast_1d(record))[0] if record is not None else self.arm.tip_xyz
        self._outcome, self._obs_stamp_ns = OUTCOME_CONTACT, self._first_obs_ns
        normal = -np.asarray(self._req.approach_dir, dtype=float) if from_approach else None
        if not self.arm.slide(self._req.slide_direction_xyz, self._req.slide_length_m, self.slide_servo, normal):
            return self._done(OUTCOME_ABORTED, f"slide: {self.arm.last_task.reason}")
        self._state = "slide"

    def _back_off(self, task) -> None:
        """The path met the object where the map said free space: keep the contact, leave the surface."""
        self._outcome, self._obs_stamp_ns = OUTCOME_CONTACT, task.contact_stamp_ns
        self._reason = f"path: {task.reason}"
        contact_xyz = fields.xyz(np.atleast_1d(task.contact))[0]
        if not self.arm.back_off(contact_xyz, self.back_off_clearance_m, task.contact_stamp_ns):
            return self._done(OUTCOME_ABORTED, f"path: {task.reason}; back_off: {self.arm.last_task.reason}")
        self._end_xyz = np.asarray(self.arm.back_off_xyz, dtype=float)
        self._state = "retract"

    def _done(self, outcome: str, reason: str) -> None:
        """End the touch; a tilted finger first goes back to its entry point and turns vertical there
        (tactile_common.finger_axis), unless nothing moved, the e-stop is engaged or it is vertical."""
        tail, arm = self._req.tail, self.arm
        if (tail is not None and self._state != "untilt" and outcome != OUTCOME_UNREACHABLE
                and not arm.estop.engaged and arm.finger_tilt_rad() > arm.cfg.max_tilt_rad):
            k0 = None if self._path_traj is None else turn_start_index(self._path_traj, arm.cfg.max_tilt_rad)
            if k0 is not None and arm.retrace(self._path_traj, k0):
                self._untilt_then, self._state = (outcome, reason), "untilt"
                return
            why = arm.last_task.reason if k0 is not None else "no planned path to go back along"
            reason = "; ".join(filter(None, [reason, f"the finger stays tilted: {why}"]))
        self._finish(outcome, reason)

    def _finish(self, outcome: str, reason: str) -> None:
        req = self._req
        travel = self._travel_planned_m if self.arm.cfg.dry_run else self.arm.odometer_m - self._odo0_m
        end = None if outcome == OUTCOME_ABORTED or self._end_xyz is None else tuple(map(float, self._end_xyz))
        slide = {}
        if req.is_slide and outcome in (OUTCOME_CONTACT, OUTCOME_FREE_SPACE):
            s = self._slide or {}
            slide = dict(slide_m=float(s.get("slid_m", 0.0)), slide_stop=str(s.get("stop", "")),
                         first_observation_stamp_ns=self._first_obs_ns,
                         contacts=(1 + int(s.get("contacts", 0))) if self._first_obs_ns is not None else 0)
        report = TouchReport(req.goal_stamp_ns, outcome, reason, self._obs_stamp_ns,
                             0.0 if outcome == OUTCOME_UNREACHABLE else travel,
                             self.arm.motion_time_s - self._t0_s + self._dwelt_s, end, **slide)
        self._req, self._state = None, "idle"
        self._publish_done(report)
