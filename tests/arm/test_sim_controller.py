"""The emulated joint_trajectory_controller: ros2_control semantics, checked against hand computations."""

import numpy as np
import pytest

from tactile_sim.controller import TrajectoryController, TrajectoryRejected

NAMES = ["a", "b"]


def ctrl():
    return TrajectoryController(NAMES, np.array([0.0, 1.0]))


def test_linear_interpolation_from_current_state_in_any_joint_order():
    c = ctrl()
    # joints given as (b, a); one point 2 s after "now" = 1.0
    c.command(1.0, ["b", "a"], [2.0], [[3.0, 2.0]])
    np.testing.assert_allclose(c.state(2.0)[0], [1.0, 2.0])  # half way: a 0->2, b 1->3
    np.testing.assert_allclose(c.state(2.0)[1], [1.0, 1.0])
    np.testing.assert_allclose(c.state(10.0)[0], [2.0, 3.0])  # holds the last point
    np.testing.assert_allclose(c.state(10.0)[1], 0.0)


def test_cubic_hermite_with_velocities():
    c = ctrl()
    c.command(0.0, NAMES, [0.0, 1.0], [[0.0, 1.0], [1.0, 1.0]], [[0.0, 0.0], [0.0, 0.0]])
    # rest-to-rest cubic: q(t) = 3t² - 2t³
    for t in (0.25, 0.5, 0.8):
        np.testing.assert_allclose(c.state(t)[0][0], 3 * t**2 - 2 * t**3, atol=1e-12)
        np.testing.assert_allclose(c.state(t)[1][0], 6 * t - 6 * t**2, atol=1e-12)


def test_new_trajectory_replaces_and_empty_one_stops_at_the_next_tick():
    c = ctrl()
    c.command(0.0, NAMES, [10.0], [[10.0, 1.0]])
    q_stop = c.state(3.0)[0]
    c.command(3.0, NAMES, [], [])  # stop: hold here
    for t in (3.01, 4.0, 20.0):
        np.testing.assert_allclose(c.state(t)[0], q_stop)
        np.testing.assert_allclose(c.state(t)[1], 0.0)
    c.command(5.0, NAMES, [1.0], [[0.0, 1.0]])  # replaces from now, starts at the held position
    np.testing.assert_allclose(c.state(5.5)[0], 0.5 * q_stop + 0.5 * np.array([0.0, 1.0]))


def test_future_start_stamp_holds_until_then():
    c = ctrl()
    c.command(0.0, NAMES, [1.0], [[1.0, 1.0]], start_s=2.0)
    np.testing.assert_allclose(c.state(1.5)[0], [0.0, 1.0])
    np.testing.assert_allclose(c.state(2.5)[0], [0.5, 1.0])


@pytest.mark.parametrize("names, times, pos, match", [
    (["a"], [1.0], [[1.0]], "do not cover"),
    (NAMES, [1.0, 0.5], [[1.0, 1.0], [2.0, 2.0]], "strictly increasing"),
    (NAMES, [1.0], [[np.nan, 1.0]], "NaN"),
    (NAMES, [1.0], [[1.0]], "positions"),
])
def test_bad_trajectories_are_rejected_and_motion_continues(names, times, pos, match):
    c = ctrl()
    c.command(0.0, NAMES, [2.0], [[2.0, 1.0]])
    with pytest.raises(TrajectoryRejected, match=match):
        c.command(1.0, names, times, pos)
    np.testing.assert_allclose(c.state(2.0)[0], [2.0, 1.0])
    assert c.rejected == 1
