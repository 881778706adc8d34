"""GoalInbox: pairing goals with paths and de-duplicating them (ROS-free)."""

from tactile_common.cycle import TouchOutcome, TouchReport
from tactile_driver.goal_inbox import GoalInbox, Verdict

STARTED = 1_000


def test_a_pair_runs_once_whichever_half_comes_first():
    box = GoalInbox(STARTED)
    assert box.add_path(5, "p") is None
    d = box.add_goal(5, "g", sent_ns=STARTED + 1)
    assert d.verdict is Verdict.RUN and (d.goal, d.path) == ("g", "p")
    box.add_goal(5, "g", sent_ns=STARTED + 2)
    assert box.add_path(5, "p").verdict is Verdict.IGNORE  # running: the planner answered twice


def test_a_finished_touch_seen_again_resends_its_report():
    box = GoalInbox(STARTED)
    box.add_goal(5, "g", STARTED + 1)
    box.add_path(5, "p")
    report = TouchReport(5, TouchOutcome.CONTACT, "", 42, 0.1, 1.0)
    box.finished(report)
    box.add_goal(5, "g", STARTED + 9)
    d = box.add_path(5, "p")
    assert d.verdict is Verdict.RESEND_REPORT and d.report == report


def test_goals_from_before_a_restart_are_not_run():
    box = GoalInbox(STARTED)
    box.add_path(5, "p")
    d = box.add_goal(5, "g", sent_ns=STARTED - 1)
    assert d.verdict is Verdict.IGNORE and "before this commander started" in d.reason
    box.add_path(6, "p")  # the explorer re-issues the touch under a new id
    assert box.add_goal(6, "g", sent_ns=STARTED + 5).verdict is Verdict.RUN


def test_an_older_goal_than_one_accepted_is_superseded_and_stale_halves_are_dropped():
    box = GoalInbox(STARTED)
    box.add_path(3, "p3")  # its goal never comes
    box.add_goal(7, "g", STARTED + 1)
    assert box.add_path(7, "p").verdict is Verdict.RUN
    assert box.add_goal(3, "g3", STARTED + 2) is None  # the old path half was dropped: no pair
    box.add_goal(4, "g", STARTED + 3)
    assert box.add_path(4, "p").verdict is Verdict.IGNORE


def test_reports_kept_are_bounded():
    box = GoalInbox(STARTED, keep=3)
    for s in range(10):
        box.finished(TouchReport(s, TouchOutcome.FREE_SPACE, "", s, 0.0, 0.0))
    assert len(box._reports) == 3


def test_after_a_restart_the_newest_goal_from_before_it_is_reported_aborted_once():
    """The touch under way when the commander died: reported at once so that the explorer re-issues it
    (it would otherwise wait its touch_timeout_s); older goals of the handed-over history are not reported."""
    box = GoalInbox(STARTED)
    assert box.orphan() is None  # nothing handed over: nothing to report
    for stamp in (3, 5, 4):  # the durable history, in any order
        box.add_path(stamp, "p")
        assert box.add_goal(stamp, "g", sent_ns=STARTED - 10 + stamp).verdict is Verdict.IGNORE
    report = box.orphan()
    assert report.goal_stamp_ns == 5 and report.outcome is TouchOutcome.ABORTED and "restarted" in report.reason
    assert report.observation_stamp_ns is None and report.travel_m == 0.0
    assert box.orphan() is None  # once
    box.finished(report)
    box.add_goal(5, "g", sent_ns=STARTED - 5)  # handed over again: its report is sent again, nothing moves
    assert box.add_path(5, "p").verdict is Verdict.RESEND_REPORT


def test_no_orphan_is_reported_once_a_newer_goal_runs_or_for_a_touch_finished_here():
    box = GoalInbox(STARTED)
    box.add_path(5, "p")
    box.add_goal(5, "g", sent_ns=STARTED - 1)
    box.add_path(6, "p")
    assert box.add_goal(6, "g", sent_ns=STARTED + 1).verdict is Verdict.RUN  # the explorer re-issued already
    assert box.orphan() is None
    box2 = GoalInbox(STARTED)
    box2.finished(TouchReport(7, TouchOutcome.CONTACT, "", 9, 0.1, 1.0))
    box2.add_path(7, "p")
    box2.add_goal(7, "g", sent_ns=STARTED - 1)
    assert box2.orphan() is None
