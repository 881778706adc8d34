"""Which contacts a graph slide gathered (tactile_bringup.slide_stream): the report's window and count."""

import numpy as np

from tactile_common.cycle import TouchOutcome, TouchReport
from tactile_common.fields import CONTACT_DTYPE, LABEL_CONTACT, LABEL_FREE_SPACE
from tactile_bringup.slide_stream import free_path, graph_slide, is_stream


def _obs(x, label=LABEL_CONTACT):
    o = np.zeros((), dtype=CONTACT_DTYPE)[()]
    o["x"], o["label"] = x, label
    return o


def _report(first, last, n, slide_m=0.1):
    return TouchReport(7, TouchOutcome.CONTACT, "", last, 0.3, 5.0, (0.4, 0.0, 0.06), slide_m, "length", first, n)


def test_the_stream_is_every_contact_in_the_window_in_stamp_order():
    obs = {5: _obs(0.1), 10: _obs(0.2), 30: _obs(0.4), 20: _obs(0.3), 25: _obs(9.0, LABEL_FREE_SPACE), 40: _obs(0.5)}
    rep = _report(10, 30, 3)
    assert is_stream(rep)
    s = graph_slide(rep, obs)
    assert s.stamps_ns == [10, 20, 30] and [float(o["x"]) for o in s.observations] == [0.2, 0.3, 0.4]
    assert s.n_contacts == 2 and s.points_xyz.shape == (2, 3) and s.stop.value == "length"


def test_the_stream_waits_for_its_last_contact_and_its_count():
    obs = {10: _obs(0.2), 20: _obs(0.3)}
    assert graph_slide(_report(10, 30, 3), obs) is None  # the last one is still on its way
    obs[30] = _obs(0.4)
    assert graph_slide(_report(10, 30, 4), obs) is None  # one in the middle too
    assert graph_slide(_report(10, 30, 3), obs) is not None


def test_pokes_and_slides_without_contact_are_not_streams():
    assert not is_stream(TouchReport(7, TouchOutcome.CONTACT, "", 10, 0.1, 1.0))
    assert not is_stream(_report(None, 10, 0, slide_m=0.0))


def test_free_path_drops_a_slide_goals_marker():
    class Goal:
        class pose:
            class position:
                x, y, z = 0.4, 0.0, 0.06

    path = np.array([[0.35, 0.0, 0.06], [0.4, 0.0, 0.06], [0.4, 0.2, 0.06]])
    np.testing.assert_array_equal(free_path(path, Goal), path[:2])
    assert free_path(None, Goal) is None
