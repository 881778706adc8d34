"""Safety box (reject, never clamp), watchdog and e-stop latch."""

import numpy as np
import pytest

from tactile_driver.safety import EStopLatch, OutsideWorkspace, Watchdog, WorkspaceBox


def box():
    return WorkspaceBox.from_params([0.25, 0.75], [-0.30, 0.30], [0.0, 0.60], 0.0, 0.005, 0.010)


def test_floor_is_table_plus_margin_plus_tip_radius():
    np.testing.assert_allclose(box().lower_xyz, [0.25, -0.30, 0.015])


@pytest.mark.parametrize("point, axis", [
    ([0.80, 0.0, 0.1], "x=0.8000"), ([0.5, -0.31, 0.1], "y=-0.3100"),
    ([0.5, 0.0, 0.01], "z=0.0100"), ([0.5, 0.0, 0.61], "z=0.6100"),
])
def test_outside_points_are_rejected(point, axis):
    path = np.array([[0.5, 0.0, 0.3], point, [0.5, 0.0, 0.3]])
    with pytest.raises(OutsideWorkspace, match=axis) as info:
        box().check(path)
    assert info.value.index == 1
    np.testing.assert_array_equal(path[1], point)  # never clamped


def test_inside_and_nan():
    b = box()
    b.check([[0.5, 0.0, 0.015], [0.75, 0.30, 0.60]])
    assert not b.inside([[np.nan, 0, 0.1]])[0]
    with pytest.raises(OutsideWorkspace, match="x=nan"):
        b.check([[np.nan, 0, 0.1]])


def test_bad_box_parameters():
    with pytest.raises(ValueError, match="min < max"):
        WorkspaceBox.from_params([0.7, 0.2], [-0.3, 0.3], [0, 0.6])
    with pytest.raises(ValueError, match="floor"):
        WorkspaceBox.from_params([0.2, 0.7], [-0.3, 0.3], [0, 0.01])


def test_watchdog():
    w = Watchdog(0.5)
    assert w.is_stale(0.0)  # no state yet
    w.feed(10.0)
    assert not w.is_stale(10.5) and w.is_stale(10.51)


def test_estop_latch():
    e = EStopLatch()
    assert e.set(True) and e.engaged
    assert not e.set(True) and e.engaged  # stays latched
    assert not e.set(False) and not e.engaged
    assert e.count == 1
