"""The explorer's side of the touch cycle, ROS-free, with an injected clock.

    WAITING_FOR_START --tip at start--> PLANNING(request) --answer ok--> TOUCHING(goal)
    TOUCHING --report + observation--> record --> PLANNING(next) | FINISHED
    TOUCHING --aborted--> BACKING_OFF --abort_backoff_s--> PLANNING(the touch again)

Delivery (docs/architecture.md, "Delivery"): events can arrive late, twice or
(if a node died) never. Every request has an id (:class:`PlanRequest`); the
planner's answer and the commander's report name it (the goal stamp is the
request id), so answers and reports of other requests are ignored. Nothing
is waited for forever:

- no answer within ``answer_timeout_s``: the same request is sent again (the
  planner answers a request it has answered before with the same answer);
- the planner answers ``timeout`` (no map new enough yet, e.g. the estimator
  is restarting): the same request again;
- no report of the touch within ``touch_timeout_s``, an ``aborted`` touch, or
  a report whose observation does not arrive within
  ``observation_timeout_s``: the touch is re-issued under a new id (a
  restarted commander does not run goals older than itself, and reports
  the newest of them ``aborted``); an ``aborted``
  touch (the commander refused or stopped it: stale joint states, e-stop) is
  re-issued only after a back-off of ``abort_backoff_s``, doubled for each
  abort in a row (2, 4, 8 s by default), so that a cause that lasts a few
  seconds (a rig that stalls, a node restarting) does not use up every retry
  at once;
- ``unreachable``: a new request (the planner excludes that target);
- the commander's report of the touch asked for comes before the planner's
  answer (the planner died after its goal went out and before its answer
  did): the report is kept, and the request is sent again at once (a
  restarted planner answers a re-sent request whose touch has ended:
  ``tactile_planner.request_inbox``);
- a planner that died and was restarted: every request carries the run's
  history (the targets chosen so far and those reported unreachable, from
  the answers and reports), so its answer is the one the dead planner
  would have given;
- more than ``max_retries`` of these in a row, ``max_unreachable``
  unreachable goals in a row, or a planner that has no goal: the run ends,
  with the reason in one line.

Times are seconds of the injected ``clock_s`` (the node passes a steady
clock: time-outs must fire even when a simulated clock stops).
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from tactile_common.cycle import PlannerAnswer, PlanRequest, TouchOutcome, TouchReport

from .progress import misses_before_contact
from .slide_stream import graph_slide, is_stream


class Phase(enum.Enum):
    WAITING_FOR_START = "waiting_for_start"
    PLANNING = "planning"
    TOUCHING = "touching"
    BACKING_OFF = "backing_off"  # an aborted touch, re-issued when the back-off ends
    FINISHED = "finished"


@dataclass(frozen=True)
class CycleConfig:
    start_tolerance_m: float = 0.003  # the tip counts as at the start position within this distance
    start_timeout_s: float = 120.0  # give up if the tip does not reach the start position
    answer_timeout_s: float = 15.0  # no answer to a request: send it again
    touch_timeout_s: float = 60.0  # no end of a touch: re-issue it
    observation_timeout_s: float = 10.0  # a report whose observation does not arrive: re-issue
    max_retries: int = 3  # re-sends / re-issues in a row before the run ends
    abort_backoff_s: float = 2.0  # an aborted touch is re-issued after this, doubled per abort in a row (0: at once)
    max_unreachable: int = 10  # unreachable goals in a row before the run ends


class ExplorationCycle:
    """Sequences the touches of one run; the node feeds it events and calls :meth:`tick`.

    ``run`` keeps the records (:class:`tactile_bringup.progress.RunRecorder`:
    ``add_touch``, ``add_travel``, ``stop_reason``, ``progress_line``,
    ``write``); ``send_request`` publishes a :class:`PlanRequest`;
    ``next_id`` gives a candidate request id (ns; made strictly increasing here).
    """

    def __init__(self, cfg: CycleConfig, start_xyz_m: np.ndarray, run: Any,
                 send_request: Callable[[PlanRequest], None], clock_s: Callable[[], float],
                 next_id: Callable[[], int], log: Any = None) -> None:
        self.cfg = cfg
        self.start_xyz_m = np.asarray(start_xyz_m, dtype=float)
        self.run = run
        self._send = send_request
        self._clock_s = clock_s
        self._next_id = next_id
        self.log = log if log is not None else logging.getLogger("exploration_cycle")
        self.phase = Phase.WAITING_FOR_START
        self.reason = ""
        self.exit_status = 0
        self.last_tip_xyz: Optional[np.ndarray] = None
        self.request: Optional[PlanRequest] = None
        self.goal_stamp_ns: Optional[int] = None
        self.report: Optional[TouchReport] = None  # of the current goal, waiting for its observation
        self._early_report: Optional[TouchReport] = None  # of the current request, before its answer
        self.last_obs_stamp_ns = 0
        self.plan_from_xyz: Optional[tuple] = tuple(map(float, self.start_xyz_m))  # nominal start of the next touch
        self.retries = 0
        self.unreachable_in_row = 0
        self.aborts_in_row = 0
        self.n_requests_sent = 0
        self.written: list[str] = []  # what run.write produced when the run ended
        self._last_id = -1
        self._t_phase = clock_s()
        self._t_sent = self._t_phase
        self._reissue_at_s = 0.0  # BACKING_OFF: when the aborted touch is re-issued
        self._goals: dict[int, Any] = {}
        self._paths: dict[int, tuple] = {}  # goal stamp -> (path (K, 3), finger axes (K, 3) or None)
        self._decision_ms: dict[int, float] = {}
        self._observations: dict[int, np.ndarray] = {}
        # The planner's memory, kept here and sent with every request (PlanRequest): the targets of the
        # goals so far (in the order they were chosen: one ok answer per goal) and those reported
        # unreachable. Not sent once an answer did not name its target.
        self._targets: dict[int, tuple] = {}  # goal stamp -> its target
        self._excluded: list[tuple] = []
        # the planner's judgment of the touches so far, as its last ok answer gave it (tactile_planner.fruitless)
        self._fruitless: Optional[tuple] = None
        self._last_target_var_m2: Optional[float] = None
        self._history_known = True

    @property
    def finished(self) -> bool:
        return self.phase is Phase.FINISHED

    # -- events -----------------------------------------------------------------
    def on_tip(self, tip_xyz_m: np.ndarray) -> None:
        if self.phase is not Phase.WAITING_FOR_START:
            return
        self.last_tip_xyz = np.asarray(tip_xyz_m, dtype=float)
        if np.linalg.norm(self.last_tip_xyz - self.start_xyz_m) <= self.cfg.start_tolerance_m:
            self.log.info("tip at the start position: first decision")
            self._new_request(0)

    def on_answer(self, answer: PlannerAnswer) -> None:
        if self.phase is not Phase.PLANNING or self.request is None or answer.request_id != self.request.request_id:
            return  # an answer to another (older, re-sent) request
        if answer.ok:
            self._remember_target(answer)
            self.goal_stamp_ns = answer.goal_stamp_ns
            self._decision_ms[answer.goal_stamp_ns] = answer.decision_ms
            self._enter(Phase.TOUCHING)
            early, self._early_report = self._early_report, None
            if early is not None and early.goal_stamp_ns == self.goal_stamp_ns:
                self.on_report(early)
        elif answer.status == "timeout":  # the planner waited for a map in vain: ask again
            self._retry(f"planner: {answer.detail}", resend=True)
        else:
            self._finish(f"planner: {answer.status}: {answer.detail}")

    def on_goal(self, stamp_ns: int, goal: Any) -> None:
        """The first goal of a stamp is kept: the one the commander runs (it runs a stamp once; a restarted
        planner that answers an old request again must not rewrite what was touched)."""
        self._goals.setdefault(int(stamp_ns), goal)

    def on_path(self, stamp_ns: int, path_xyz: np.ndarray, axes_xyz: Optional[np.ndarray] = None) -> None:
        """The planned free-space path of a goal (world, (K, 3)) and its finger axes ((K, 3), optional;
        kept only for a tilted finger): drawn in the figure, the rod checked along it. The first is kept."""
        axes = None if axes_xyz is None else np.asarray(axes_xyz, dtype=float).reshape(-1, 3)
        if axes is not None and np.allclose(axes, [0.0, 0.0, 1.0]):
            axes = None
        self._paths.setdefault(int(stamp_ns), (np.asarray(path_xyz, dtype=float).reshape(-1, 3), axes))

    def on_observation(self, stamp_ns: int, point: np.ndarray) -> None:
        self._observations[int(stamp_ns)] = point
        if self.report is not None:
            self._complete()

    def on_report(self, report: TouchReport) -> None:
        if (self.phase is Phase.PLANNING and self.request is not None and self._early_report is None
                and report.goal_stamp_ns == self.request.request_id):
            self._early_report = report  # the touch ended, its answer was lost: ask again now
            self.log.warning(f"touch {report.goal_stamp_ns} ended before the planner's answer to it arrived: "
                             f"sending request {report.goal_stamp_ns} again")
            self._publish()
            return
        if self.phase is not Phase.TOUCHING or report.goal_stamp_ns != self.goal_stamp_ns or self.report is not None:
            return  # another goal's report, or this one's again
        if report.outcome is TouchOutcome.UNREACHABLE:
            if report.goal_stamp_ns in self._targets:
                self._excluded.append(self._targets[report.goal_stamp_ns])
            self.unreachable_in_row += 1
            self.run.add_travel(report.travel_m, report.duration_s)
            self.log.warning(f"goal unreachable ({self.unreachable_in_row} in a row): re-planning")
            if self.unreachable_in_row >= self.cfg.max_unreachable:
                self._finish(f"{self.unreachable_in_row} unreachable goals in a row")
            else:
                self._new_request(self.last_obs_stamp_ns)
            return
        if report.outcome is TouchOutcome.ABORTED:
            self.run.add_travel(report.travel_m, report.duration_s)
            self.plan_from_xyz = None  # the arm stopped somewhere: plan from its measured pose
            self.aborts_in_row += 1
            self._retry(f"touch aborted: {report.reason}", resend=False, backoff=True)
            return
        self.report = report
        self.plan_from_xyz = report.end_xyz_m
        self._t_phase = self._clock_s()  # now waiting for the observation
        self._complete()

    def tick(self) -> None:
        """Time-outs; call periodically."""
        waited = self._clock_s() - self._t_phase
        if self.phase is Phase.WAITING_FOR_START and waited > self.cfg.start_timeout_s:
            self._finish(self._start_failure(), exit_status=1)
        elif self.phase is Phase.BACKING_OFF and self._clock_s() >= self._reissue_at_s:
            self._new_request(self.last_obs_stamp_ns)
        elif self.phase is Phase.PLANNING and self._clock_s() - self._t_sent > self.cfg.answer_timeout_s:
            self._retry(f"no answer to request {self.request.request_id} within {self.cfg.answer_timeout_s:.0f} s",
                        resend=True)
        elif self.phase is Phase.TOUCHING and self.report is None and waited > self.cfg.touch_timeout_s:
            self.plan_from_xyz = None  # where the arm is, nobody said
            self._retry(f"touch {self.goal_stamp_ns} did not end within {self.cfg.touch_timeout_s:.0f} s",
                        resend=False)
        elif self.phase is Phase.TOUCHING and self.report is not None and waited > self.cfg.observation_timeout_s:
            self._retry(f"the observation {self.report.observation_stamp_ns} of touch {self.goal_stamp_ns} "
                        f"did not arrive within {self.cfg.observation_timeout_s:.0f} s", resend=False)

    def interrupt(self, reason: str = "interrupted") -> None:
        """Ctrl-C: keep what was measured."""
        self._finish(reason)

    # -- internals --------------------------------------------------------------
    def _complete(self) -> None:
        report = self.report
        obs_ns = report.observation_stamp_ns
        if obs_ns is None or obs_ns not in self._observations:
            return  # still on its way: tick() bounds the wait
        extra = {}
        if is_stream(report):  # a slide: every contact of its stream (tactile_bringup.slide_stream)
            slide = graph_slide(report, self._observations)
            if slide is None:
                return  # some of the stream still on its way: tick() bounds the wait
            for stamp in slide.stamps_ns:
                self._observations.pop(stamp, None)
            self._observations[obs_ns] = slide.observations[-1]
            extra["slide"] = slide
        self.report = None
        self.retries = self.unreachable_in_row = self.aborts_in_row = 0
        path, axes = self._paths.pop(report.goal_stamp_ns, (None, None))
        record = self.run.add_touch(goal=self._goals.pop(report.goal_stamp_ns, None),
                                    observation=self._observations.pop(obs_ns), travel_m=report.travel_m,
                                    time_s=report.duration_s,
                                    decision_ms=self._decision_ms.pop(report.goal_stamp_ns, float("nan")),
                                    path_xyz=path, path_axes_xyz=axes, **extra)
        self.log.info(self.run.progress_line(record))
        self.last_obs_stamp_ns = obs_ns
        reason = self.run.stop_reason()
        if reason:
            self._finish(reason)
        else:
            self._new_request(obs_ns)

    def _new_request(self, min_map_stamp_ns: int) -> None:
        request_id = max(int(self._next_id()), self._last_id + 1)
        self._last_id = request_id
        history = (tuple(self._targets.values()), tuple(self._excluded)) if self._history_known else (None, None)
        judged = (self._fruitless, self._last_target_var_m2) if self._history_known else (None, None)
        self.request = PlanRequest(request_id, int(min_map_stamp_ns), self.plan_from_xyz, *history,
                                   misses_before_contact(self.run.touches), *judged)
        self.goal_stamp_ns, self.report, self._early_report = None, None, None
        self._enter(Phase.PLANNING)
        self._publish()

    def _publish(self) -> None:
        self._t_sent = self._clock_s()
        self.n_requests_sent += 1
        self._send(self.request)

    def _retry(self, why: str, resend: bool, backoff: bool = False) -> None:
        self.retries += 1
        if self.retries > self.cfg.max_retries:
            self._finish(f"{why}; gave up after {self.cfg.max_retries} retries", exit_status=1)
            return
        wait_s = self.cfg.abort_backoff_s * 2.0 ** (self.aborts_in_row - 1) if backoff else 0.0
        if resend:
            self.log.warning(f"{why}: sending request {self.request.request_id} again "
                             f"({self.retries}/{self.cfg.max_retries})")
            self._publish()
        elif wait_s > 0:
            self.log.warning(f"{why}: re-issuing the touch in {wait_s:g} s ({self.retries}/{self.cfg.max_retries})")
            self.request, self.goal_stamp_ns, self.report = None, None, None
            self._reissue_at_s = self._clock_s() + wait_s
            self._enter(Phase.BACKING_OFF)
        else:
            self.log.warning(f"{why}: re-issuing the touch ({self.retries}/{self.cfg.max_retries})")
            self._new_request(self.last_obs_stamp_ns)

    def _remember_target(self, answer: PlannerAnswer) -> None:
        try:
            target = answer.target_xyz_m
        except ValueError:
            target = None
        if target is None:
            if self._history_known:
                self.log.warning(f"planner answer {answer.request_id} does not name its target: requests carry "
                                 "no history from now on (a restarted planner may then repeat earlier targets)")
            self._history_known = False
            return
        self._targets[answer.goal_stamp_ns] = target
        try:  # an answer without them (an older planner): the planner keeps its own memory
            self._fruitless, self._last_target_var_m2 = answer.fruitless_xyz_m, answer.target_var_m2
        except ValueError as exc:
            self.log.warning(f"planner answer {answer.request_id}: {exc}; not handed back")
            self._fruitless = self._last_target_var_m2 = None

    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self._t_phase = self._clock_s()

    def _start_failure(self) -> str:
        """Why the first decision never went out, in the words a rig user acts on."""
        if self.last_tip_xyz is None:
            return (f"no fingertip pose within {self.cfg.start_timeout_s:.0f} s (is the arm commander running?)")
        start = np.round(self.start_xyz_m, 3).tolist()
        return (f"the fingertip never reached the start position {start} within {self.cfg.start_timeout_s:.0f} s: "
                f"it is at {np.round(self.last_tip_xyz, 3).tolist()} (see the arm commander's log)")

    def _finish(self, reason: str, exit_status: int = 0) -> None:
        if self.finished:
            return
        self.phase, self.reason = Phase.FINISHED, reason
        self.exit_status = exit_status or self.exit_status
        self.written = list(self.run.write(reason) or [])
