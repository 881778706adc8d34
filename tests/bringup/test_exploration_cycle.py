"""The explorer's touch cycle with a fake clock: ids, re-sends, re-issues, duplicates, stop rules."""

import numpy as np
import pytest

from tactile_bringup.exploration_cycle import CycleConfig, ExplorationCycle, Phase
from tactile_common.cycle import PlannerAnswer, PlanRequest, TouchOutcome, TouchReport

START = np.array([0.33, 0.0, 0.06])
MISS = np.ones(1)  # the fake observation of a touch that met nothing


class FakeRun:
    def __init__(self, touches=3):
        self.budget, self.touches, self.travel, self.written = touches, [], [], None

    def add_touch(self, goal, observation, travel_m, time_s, decision_ms, path_xyz=None, path_axes_xyz=None):
        """A record as RunRecorder's: ``contact`` None for a miss (the observation MISS)."""
        self.touches.append({"index": len(self.touches), "contact": None if observation is MISS else observation,
                             "travel_m": travel_m, "decision_ms": decision_ms, "path": path_xyz,
                             "path_axes": path_axes_xyz})
        return {"index": len(self.touches) - 1}

    def add_travel(self, travel_m, time_s):
        self.travel.append(travel_m)

    def stop_reason(self):
        return "touch budget" if len(self.touches) >= self.budget else None

    def progress_line(self, record):
        return f"touch {record['index'] + 1}"

    def write(self, reason):
        self.written = reason
        return ["report.json"]


class Rig:
    """The cycle plus a fake steady clock, a fake id clock and the requests it sent."""

    def __init__(self, touches=3, **cfg):
        self.t = 0.0
        self.sent = []
        self.run = FakeRun(touches)
        self.cycle = ExplorationCycle(CycleConfig(**cfg), START, self.run, self.sent.append, lambda: self.t,
                                      lambda: int(self.t * 1e9))

    def advance(self, dt):
        self.t += dt
        self.cycle.tick()

    def answer(self, request=None, status="ok", detail="", target=None, judged=None):
        req = request or self.sent[-1]
        extra = None if target is None else {"target_xyz_m": ",".join(map(repr, target))}
        if judged is not None:  # the planner's judgment: (fruitless targets text, the target's variance text)
            extra.update(fruitless_xyz_m=judged[0], target_var_m2=judged[1])
        self.cycle.on_answer(PlannerAnswer(req.request_id, status, detail, req.request_id if status == "ok" else 0, 5.0,
                                           extra))

    def report(self, outcome=TouchOutcome.CONTACT, obs_ns=None, goal_ns=None):
        goal_ns = self.sent[-1].request_id if goal_ns is None else goal_ns
        self.cycle.on_report(TouchReport(goal_ns, outcome, "", obs_ns, 0.1, 2.0))

    def touch(self, obs_ns, contact=True):
        self.answer()
        self.cycle.on_observation(obs_ns, np.zeros(1) if contact else MISS)
        self.report(TouchOutcome.CONTACT if contact else TouchOutcome.FREE_SPACE, obs_ns=obs_ns)


def test_first_request_waits_for_the_tip_at_the_start():
    r = Rig()
    r.cycle.on_tip(START + [0.01, 0, 0])
    assert not r.sent and r.cycle.phase is Phase.WAITING_FOR_START
    r.cycle.on_tip(START + [0.001, 0, 0])
    assert len(r.sent) == 1 and r.sent[0].min_map_stamp_ns == 0
    r.cycle.on_tip(START)  # later poses start nothing more
    assert len(r.sent) == 1


def test_a_run_of_touches_asks_for_maps_with_each_observation_and_stops_at_the_budget():
    r = Rig(touches=3)
    r.cycle.on_tip(START)
    for k, obs in enumerate((11, 22, 33)):
        r.advance(1.0)
        r.touch(obs)
    assert [q.min_map_stamp_ns for q in r.sent] == [0, 11, 22]
    ids = [q.request_id for q in r.sent]
    assert ids == sorted(set(ids))  # unique and increasing
    assert r.cycle.finished and r.run.written == "touch budget" and r.cycle.exit_status == 0


def test_requests_count_the_misses_until_the_first_contact():
    """The planner's search_after_misses needs the run's misses before any contact, also after a
    restart (it keeps no state): each request carries them, 0 from the first contact on."""
    r = Rig(touches=5)
    r.cycle.on_tip(START)
    for obs, contact in ((1, False), (2, False), (3, True), (4, False)):
        r.touch(obs, contact)
    assert [q.misses_before_contact for q in r.sent] == [0, 1, 2, 0, 0]
    assert PlanRequest.from_values(r.sent[2].values()) == r.sent[2]  # it travels in the message


def test_ids_stay_strictly_increasing_when_the_clock_does_not_move():
    r = Rig(touches=3)
    r.cycle.on_tip(START)
    r.touch(1)
    r.touch(2)
    ids = [q.request_id for q in r.sent]
    assert ids == [0, 1, 2]


def test_an_unanswered_request_is_sent_again_with_the_same_id_then_the_run_gives_up():
    r = Rig(answer_timeout_s=5.0, max_retries=2)
    r.cycle.on_tip(START)
    r.advance(4.9)
    assert len(r.sent) == 1
    r.advance(0.2)
    assert len(r.sent) == 2 and r.sent[1] == r.sent[0]
    r.advance(5.1)
    assert len(r.sent) == 3 and r.sent[2] == r.sent[0]
    r.advance(5.1)
    assert r.cycle.finished and r.cycle.exit_status == 1 and "gave up after 2 retries" in r.cycle.reason
    assert "no answer to request" in r.cycle.reason


def test_a_late_answer_after_a_resend_is_taken_and_duplicates_are_ignored():
    r = Rig(answer_timeout_s=5.0)
    r.cycle.on_tip(START)
    r.advance(6.0)  # re-sent once
    r.answer(r.sent[0])
    r.answer(r.sent[0])  # the answer to the re-send: the same answer again
    assert r.cycle.phase is Phase.TOUCHING and len(r.sent) == 2


def test_a_report_before_the_answer_is_kept_and_the_request_sent_again_at_once():
    """The planner died after its goal went out and before its answer did: the commander ran the touch."""
    r = Rig(answer_timeout_s=15.0)
    r.cycle.on_tip(START)
    asked = r.sent[-1]
    r.cycle.on_observation(5, np.zeros(1))
    r.report(obs_ns=5)
    assert r.cycle.phase is Phase.PLANNING and not r.run.touches
    assert len(r.sent) == 2 and r.sent[1] == asked  # at once, not after answer_timeout_s
    r.report(obs_ns=5)  # the commander's report again: no second re-send
    assert len(r.sent) == 2
    r.answer(asked)  # the restarted planner's answer to the re-send
    assert len(r.run.touches) == 1 and r.sent[-1].min_map_stamp_ns == 5 and r.sent[-1].request_id > asked.request_id
    r.answer()  # the next touch: no early report left over
    assert r.cycle.phase is Phase.TOUCHING and len(r.run.touches) == 1


def test_answers_and_reports_of_other_requests_are_ignored():
    r = Rig()
    r.cycle.on_tip(START)
    first = r.sent[-1]
    r.cycle.on_answer(PlannerAnswer(first.request_id + 99, "ok", "", first.request_id + 99))
    assert r.cycle.phase is Phase.PLANNING
    r.answer()
    r.cycle.on_observation(5, np.zeros(1))
    r.report(obs_ns=5, goal_ns=first.request_id + 99)  # another goal's report (history, a stray touch)
    assert not r.run.touches
    r.report(obs_ns=5)
    assert len(r.run.touches) == 1


def test_a_report_waits_for_its_observation_and_a_missing_one_reissues_the_touch():
    r = Rig(observation_timeout_s=3.0)
    r.cycle.on_tip(START)
    r.answer()
    r.report(obs_ns=77)
    assert not r.run.touches and r.cycle.phase is Phase.TOUCHING
    r.cycle.on_observation(77, np.ones(1))  # arrives after the report: the touch completes
    assert len(r.run.touches) == 1 and r.sent[-1].min_map_stamp_ns == 77
    r.answer()
    r.report(obs_ns=88)
    r.advance(3.1)  # never arrives: the touch is re-issued under a new id
    assert r.sent[-1].min_map_stamp_ns == 77 and r.sent[-1].request_id > r.sent[-2].request_id
    assert len(r.run.touches) == 1


def test_a_touch_that_never_ends_is_reissued_under_a_new_id():
    r = Rig(touch_timeout_s=10.0, max_retries=1)
    r.cycle.on_tip(START)
    r.advance(1.0)
    r.answer()
    r.advance(10.5)
    assert len(r.sent) == 2 and r.sent[1].request_id > r.sent[0].request_id
    assert r.sent[1].min_map_stamp_ns == r.sent[0].min_map_stamp_ns
    r.answer()
    r.advance(10.5)
    assert r.cycle.finished and r.cycle.exit_status == 1 and "did not end" in r.cycle.reason


def test_the_planner_waiting_in_vain_for_a_map_makes_the_explorer_ask_again():
    r = Rig()
    r.cycle.on_tip(START)
    r.answer(status="timeout", detail="no goal after 30 s: still waiting for a map")
    assert len(r.sent) == 2 and r.sent[1] == r.sent[0] and not r.cycle.finished


def test_a_planner_without_a_goal_ends_the_run_with_its_reason():
    r = Rig()
    r.cycle.on_tip(START)
    r.answer(status="no_candidates", detail="the estimate lost the object")
    assert r.cycle.finished and r.run.written == "planner: no_candidates: the estimate lost the object"


def test_unreachable_goals_ask_for_a_new_plan_on_the_same_map_until_the_limit():
    r = Rig(max_unreachable=2)
    r.cycle.on_tip(START)
    r.touch(9)
    r.answer()
    r.report(TouchOutcome.UNREACHABLE)
    assert r.sent[-1].min_map_stamp_ns == 9 and not r.cycle.finished
    r.answer()
    r.report(TouchOutcome.UNREACHABLE)
    assert r.cycle.finished and r.cycle.reason == "2 unreachable goals in a row"


def test_an_aborted_touch_is_reissued_and_its_travel_counted():
    r = Rig(abort_backoff_s=0.0)
    r.cycle.on_tip(START)
    r.answer()
    r.report(TouchOutcome.ABORTED)
    assert len(r.sent) == 2 and r.run.travel == [0.1] and not r.cycle.finished


def test_aborted_touches_are_reissued_after_a_doubling_back_off_so_a_stall_does_not_use_every_retry():
    """Seen on the graph: a rig stalled 2.5 s after the commander's restart, the commander aborted the path
    (stale joint states) and the three re-issues, sent at once, were refused within 0.1 s: the run ended.
    With the back-off the re-issues are 2, 4 and 8 s apart and a stall shorter than that is ridden out."""
    r = Rig(abort_backoff_s=2.0, max_retries=3)
    r.cycle.on_tip(START)
    r.answer()
    for k, wait_s in enumerate((2.0, 4.0, 8.0)):
        r.report(TouchOutcome.ABORTED)
        assert len(r.sent) == k + 1 and r.cycle.phase is Phase.BACKING_OFF
        r.answer(r.sent[-1])  # a late answer to the aborted goal's request changes nothing
        r.advance(wait_s - 0.01)
        assert len(r.sent) == k + 1 and r.cycle.phase is Phase.BACKING_OFF
        r.advance(0.02)
        assert len(r.sent) == k + 2 and r.cycle.phase is Phase.PLANNING
        assert r.sent[-1].request_id > r.sent[-2].request_id and r.sent[-1].start_xyz_m is None
        r.answer()
    r.report(TouchOutcome.ABORTED)  # the fourth abort in a row: the run ends, with the reason
    assert r.cycle.finished and r.cycle.exit_status == 1 and "gave up after 3 retries" in r.cycle.reason


def test_a_touch_that_succeeds_after_an_abort_resets_the_back_off():
    r = Rig(touches=5, abort_backoff_s=2.0)
    r.cycle.on_tip(START)
    r.answer()
    r.report(TouchOutcome.ABORTED)
    r.advance(2.01)
    r.touch(7)
    assert len(r.run.touches) == 1
    r.report(TouchOutcome.ABORTED)  # a new abort waits the first back-off again, not the doubled one
    r.advance(2.01)
    assert r.cycle.phase is Phase.PLANNING


def test_the_tip_never_at_the_start_says_where_it_is():
    r = Rig(start_timeout_s=5.0)
    r.cycle.on_tip(START + [0.1, 0, 0])
    r.advance(5.1)
    assert r.cycle.finished and r.cycle.exit_status == 1 and "never reached the start position" in r.cycle.reason


def test_interrupt_keeps_what_was_measured_once():
    r = Rig(touches=5)
    r.cycle.on_tip(START)
    r.touch(1)
    r.cycle.interrupt()
    r.cycle.interrupt()
    assert r.run.written == "interrupted" and len(r.run.touches) == 1


@pytest.mark.parametrize("outcome", ["contact", "free_space", "unreachable", "aborted"])
def test_reports_round_trip_through_their_key_values(outcome):
    rep = TouchReport(123, TouchOutcome(outcome), "why", None if outcome == "aborted" else 456, 0.25, 3.5)
    assert TouchReport.from_values(outcome, rep.values()) == rep


def test_an_unknown_outcome_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown touch outcome 'exploded'"):
        TouchReport.from_values("exploded", {})


def test_each_request_names_the_nominal_start_of_its_touch():
    r = Rig(touches=5)
    r.cycle.on_tip(START + [0.002, 0, 0])  # measured: near the start, not on it
    assert r.sent[0].start_xyz_m == tuple(START)
    r.answer()
    r.cycle.on_observation(5, np.zeros(1))
    r.cycle.on_report(TouchReport(r.sent[-1].request_id, TouchOutcome.CONTACT, "", 5, 0.1, 1.0, (0.4, 0.1, 0.06)))
    assert r.sent[-1].start_xyz_m == (0.4, 0.1, 0.06)
    r.answer()
    r.report(TouchOutcome.UNREACHABLE)  # nothing moved: same start
    assert r.sent[-1].start_xyz_m == (0.4, 0.1, 0.06)
    r.answer()
    r.report(TouchOutcome.ABORTED)  # stopped somewhere: the planner uses the measured pose
    r.advance(CycleConfig().abort_backoff_s)  # re-issued after the back-off
    assert r.sent[-1].start_xyz_m is None


def test_every_request_carries_the_targets_so_far_and_those_reported_unreachable():
    """The planner's memory travels with the request: a restarted planner is told the history."""
    r = Rig(touches=5)
    r.cycle.on_tip(START)
    assert r.sent[0].visited_xyz_m == () and r.sent[0].excluded_xyz_m == ()
    a, b, c = (0.41, 0.01, 0.06), (0.45, -0.02, 0.06), (0.5, 0.03, 0.06)
    r.answer(target=a)
    r.cycle.on_observation(5, np.zeros(1))
    r.report(obs_ns=5)
    assert r.sent[-1].visited_xyz_m == (a,) and r.sent[-1].excluded_xyz_m == ()
    r.answer(target=b)
    r.report(TouchOutcome.UNREACHABLE)
    assert r.sent[-1].visited_xyz_m == (a, b) and r.sent[-1].excluded_xyz_m == (b,)
    r.advance(CycleConfig().answer_timeout_s + 1)  # a re-sent request is the same request, history included
    assert r.sent[-1] == r.sent[-2]
    r.answer(target=c)
    r.report(TouchOutcome.ABORTED)  # re-issued: the aborted goal's target is a target chosen so far
    r.advance(CycleConfig().abort_backoff_s)
    assert r.sent[-1].visited_xyz_m == (a, b, c) and r.sent[-1].excluded_xyz_m == (b,)
    # through the request's key/values, bit for bit
    assert PlanRequest.from_values(r.sent[-1].values()) == r.sent[-1]


def test_every_request_hands_back_the_planners_last_judgment_of_the_touches():
    """Fruitless touches (tactile_planner.fruitless) and the last target's variance: as the last ok answer
    gave them, bit for bit, so a restarted planner judges the last touch as the one that died would."""
    r = Rig(touches=5)
    r.cycle.on_tip(START)
    assert r.sent[0].fruitless_xyz_m is None and r.sent[0].last_target_var_m2 is None  # nothing to hand back
    a, b = (0.41, 0.01, 0.06), (0.45, -0.02, 0.06)
    r.answer(target=a, judged=("", repr(1.25e-4)))
    r.cycle.on_observation(5, np.zeros(1))
    r.report(obs_ns=5)
    assert r.sent[-1].fruitless_xyz_m == () and r.sent[-1].last_target_var_m2 == 1.25e-4
    r.answer(target=b, judged=(",".join(map(repr, a)), repr(3.5e-5)))
    r.cycle.on_observation(6, np.zeros(1))
    r.report(obs_ns=6)
    assert r.sent[-1].fruitless_xyz_m == (a,) and r.sent[-1].last_target_var_m2 == 3.5e-5
    assert PlanRequest.from_values(r.sent[-1].values()) == r.sent[-1]
    with pytest.raises(ValueError, match="last_target_var_m2 must be a finite number"):
        PlanRequest.from_values({"request_id": "1", "last_target_var_m2": "nan"})


def test_an_answer_without_its_target_stops_the_history_rather_than_sending_a_wrong_one():
    r = Rig(touches=5)
    r.cycle.on_tip(START)
    r.answer()  # a planner that does not name its target
    r.cycle.on_observation(5, np.zeros(1))
    r.report(obs_ns=5)
    assert r.sent[-1].visited_xyz_m is None and r.sent[-1].excluded_xyz_m is None
    assert "visited_xyz_m" not in r.sent[-1].values()


@pytest.mark.parametrize("text", ["0.4,0.1", "0.4,0.1,nan", "a,b,c", "0.4,0.1,0.06;"])
def test_a_malformed_history_is_a_clear_error(text):
    with pytest.raises(ValueError, match="visited_xyz_m must be three finite numbers"):
        PlanRequest.from_values({"request_id": "1", "visited_xyz_m": text})


def test_a_tilted_paths_axes_reach_the_touchs_record_and_a_vertical_ones_do_not():
    r = Rig(touches=2)
    r.cycle.on_tip(START)
    path = np.array([START, [0.4, 0.05, 0.1], [0.4, 0.05, 0.1], [0.42, 0.05, 0.08]])
    tilted = np.array([[0, 0, 1.0], [0, 0, 1.0], [0.7071, 0, 0.7071], [0.7071, 0, 0.7071]])
    for axes in (tilted, np.tile([0.0, 0.0, 1.0], (4, 1))):
        r.cycle.on_path(r.sent[-1].request_id, path, axes)
        r.touch(obs_ns=len(r.run.touches) + 1)
    np.testing.assert_array_equal(r.run.touches[0]["path_axes"], tilted)
    np.testing.assert_array_equal(r.run.touches[1]["path"], path)
    assert r.run.touches[1]["path_axes"] is None
