"""Which goal + path pairs the arm commander runs: pairing and de-duplication, ROS-free.

A goal (``/planner/goal``) and its path (``/planner/path``) carry the same
``header.stamp``: the id of the plan request they answer
(:mod:`tactile_common.cycle`). Both topics are durable, so the commander sees
a pair again when the planner answers a request twice (it restarted, or the
explorer re-sent the request) and sees the recent history of pairs when it
restarts itself. The rules, in order:

1. a pair whose touch already finished: re-send that touch's report (the
   explorer may have missed it), move nothing;
2. the pair being run or waiting: nothing;
3. a pair whose goal was published before this commander started (history
   handed over after a restart): nothing — the arm holds still until the
   explorer re-issues the touch under a new id. The newest such pair may be
   the touch the explorer is waiting for: :meth:`GoalInbox.orphan` reports
   it ``aborted`` once (the node asks when its start-up move is done), so the
   explorer re-issues it at once rather than after its ``touch_timeout_s``.
   If that touch had finished before the restart, the explorer and the
   re-analysis keep the first report of a goal and ignore this one;
4. a pair older than the newest one accepted: superseded, nothing;
5. otherwise: run it.

Times: ``sent_ns`` is the publisher's wall-clock send time of the goal
(DDS source timestamp), ``started_ns`` the commander's wall-clock start.
"""

from __future__ import annotations

import enum
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Optional

from tactile_common.cycle import TouchOutcome, TouchReport


class Verdict(enum.Enum):
    RUN = "run"
    RESEND_REPORT = "resend_report"
    IGNORE = "ignore"


@dataclass(frozen=True)
class Decision:
    verdict: Verdict
    stamp_ns: int
    goal: Any = None
    path: Any = None
    report: Optional[TouchReport] = None
    reason: str = ""


class GoalInbox:
    """Pairs goals with paths by stamp and applies the rules of the module docstring."""

    def __init__(self, started_ns: int, keep: int = 200) -> None:
        self.started_ns = int(started_ns)
        self.keep = int(keep)
        self._goals: dict[int, tuple[Any, int]] = {}  # stamp -> (goal, sent_ns)
        self._paths: dict[int, Any] = {}
        self._reports: OrderedDict[int, TouchReport] = OrderedDict()  # finished touches, newest last
        self._accepted: set[int] = set()  # run or running, not yet finished
        self.newest_accepted_ns = -1
        self.newest_old_ns = -1  # the newest pair published before this commander started
        self._orphan_reported_ns = -1

    def add_goal(self, stamp_ns: int, goal: Any, sent_ns: int) -> Optional[Decision]:
        self._goals[int(stamp_ns)] = (goal, int(sent_ns))
        return self._pair(int(stamp_ns))

    def add_path(self, stamp_ns: int, path: Any) -> Optional[Decision]:
        self._paths[int(stamp_ns)] = path
        return self._pair(int(stamp_ns))

    def finished(self, report: TouchReport) -> None:
        """Remember a finished touch (its report is re-sent if its goal comes again)."""
        self._accepted.discard(report.goal_stamp_ns)
        self._reports[report.goal_stamp_ns] = report
        while len(self._reports) > self.keep:
            self._reports.popitem(last=False)

    def orphan(self) -> Optional[TouchReport]:
        """The newest pair from before this commander started, as an ``aborted`` report, once; None when
        there is none, it was reported, it finished here, or a newer goal has been accepted since."""
        stamp = self.newest_old_ns
        if stamp <= self._orphan_reported_ns or stamp <= self.newest_accepted_ns or stamp in self._reports:
            return None
        self._orphan_reported_ns = stamp
        return TouchReport(stamp, TouchOutcome.ABORTED, "the commander restarted: a goal published before it "
                           "started is not run", None, 0.0, 0.0)

    def _pair(self, stamp_ns: int) -> Optional[Decision]:
        if stamp_ns not in self._goals or stamp_ns not in self._paths:
            return None  # the other half is on its way
        (goal, sent_ns), path = self._goals.pop(stamp_ns), self._paths.pop(stamp_ns)
        for table in (self._goals, self._paths):  # halves older than a complete pair never pair up
            for old in [s for s in table if s < stamp_ns]:
                table.pop(old)
        if stamp_ns in self._reports:
            return Decision(Verdict.RESEND_REPORT, stamp_ns, report=self._reports[stamp_ns],
                            reason="touch already done: report sent again")
        if stamp_ns in self._accepted:
            return Decision(Verdict.IGNORE, stamp_ns, reason="already running or queued")
        if sent_ns < self.started_ns:
            self.newest_old_ns = max(self.newest_old_ns, stamp_ns)
            return Decision(Verdict.IGNORE, stamp_ns, reason="published before this commander started "
                            "(the newest is reported aborted after the start-up move)")
        if stamp_ns < self.newest_accepted_ns:
            return Decision(Verdict.IGNORE, stamp_ns, reason="superseded by a newer goal")
        self._accepted.add(stamp_ns)
        self.newest_accepted_ns = stamp_ns
        return Decision(Verdict.RUN, stamp_ns, goal=goal, path=path)
