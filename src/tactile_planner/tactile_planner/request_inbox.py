"""Which plan requests the planner answers, and how: de-duplication, ROS-free.

Requests (``/planner/request``) and touch reports (``/arm/touch_done``) are
durable (docs/architecture.md, "Delivery"), so the planner sees a request
again when the explorer re-sends it, and a restarted planner is handed the
recent history of both. The rules, in order:

1. a request answered before: the stored answer again, unchanged;
2. a request whose touch has ended, seen for the first time: nothing (the
   history handed over after a restart; planning it would only waste time);
3. the same, seen again: plan it. The explorer re-sends only the request it
   still waits for, so the dead planner's answer was lost with it (it
   published the goal, the commander ran the touch, and then it died before
   its status went out). The request carries the run's history, so the new
   answer is the one that was lost;
4. a request older than the newest one seen: superseded, nothing;
5. otherwise: plan it (when a new enough map is there).
"""

from __future__ import annotations

import enum
from collections import OrderedDict
from typing import Any, Optional

KEEP_ANSWERS = 200  # answered requests kept for re-sending


class Verdict(enum.Enum):
    PLAN = "plan"
    RESEND_ANSWER = "resend_answer"
    IGNORE = "ignore"


class RequestInbox:
    """The planner's memory of requests: answers given, touches ended, ended requests seen once."""

    def __init__(self, keep_answers: int = KEEP_ANSWERS) -> None:
        self.keep_answers = keep_answers
        self.answers: OrderedDict[int, Any] = OrderedDict()  # request id -> the answer (any object)
        self.ended: set[int] = set()  # request ids (= goal stamps) whose touch has ended
        self._ended_seen_once: set[int] = set()
        self.newest_id = -1

    def on_request(self, request_id: int) -> tuple[Verdict, Optional[Any]]:
        """The verdict for a request just received, and the stored answer with RESEND_ANSWER."""
        if request_id in self.answers:
            return Verdict.RESEND_ANSWER, self.answers[request_id]
        if request_id in self.ended and request_id not in self._ended_seen_once:
            self._ended_seen_once.add(request_id)
            return Verdict.IGNORE, None
        if request_id < self.newest_id:
            return Verdict.IGNORE, None
        self.newest_id = request_id
        return Verdict.PLAN, None

    def answered(self, request_id: int, answer: Any) -> None:
        self.answers[request_id] = answer
        while len(self.answers) > self.keep_answers:
            self.answers.popitem(last=False)

    def touch_ended(self, request_id: int) -> None:
        self.ended.add(request_id)
