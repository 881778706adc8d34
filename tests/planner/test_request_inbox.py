"""RequestInbox: which plan requests the planner answers (ROS-free)."""

from tactile_planner.request_inbox import RequestInbox, Verdict


def test_a_request_is_planned_once_then_its_stored_answer_is_sent_again():
    box = RequestInbox()
    assert box.on_request(5) == (Verdict.PLAN, None)
    box.answered(5, "answer 5")
    assert box.on_request(5) == (Verdict.RESEND_ANSWER, "answer 5")
    box.touch_ended(5)
    assert box.on_request(5) == (Verdict.RESEND_ANSWER, "answer 5")  # ended, but answered: the same answer


def test_older_requests_than_the_newest_are_superseded():
    box = RequestInbox()
    assert box.on_request(9)[0] is Verdict.PLAN
    assert box.on_request(3)[0] is Verdict.IGNORE
    assert box.on_request(10)[0] is Verdict.PLAN


def test_an_ended_request_is_skipped_when_handed_over_and_planned_when_sent_again():
    """A restarted planner: the durable history hands over requests whose touches ended (skipped), but the
    explorer re-sends the one whose answer died with the old planner: that one is planned."""
    box = RequestInbox()
    for ended in (1, 2, 3):
        box.touch_ended(ended)
    for handed_over in (1, 2, 3):
        assert box.on_request(handed_over)[0] is Verdict.IGNORE
    assert box.on_request(3)[0] is Verdict.PLAN  # the re-send
    box.answered(3, "answer 3")
    assert box.on_request(3) == (Verdict.RESEND_ANSWER, "answer 3")
    assert box.on_request(4)[0] is Verdict.PLAN


def test_answers_kept_are_bounded():
    box = RequestInbox(keep_answers=2)
    for k in range(4):
        box.on_request(k)
        box.answered(k, k)
    assert list(box.answers) == [2, 3]
