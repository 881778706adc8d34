"""The rig's lock-step with the sensing loop (tactile_sim.clock_gate), ticked by hand.

Each case plays the clock forward tick by tick with a wall clock of its own and
counts where it stops, against the rule written out here: hold while the
driver's or the commander's progress is more than max_lag behind, at most
max_lag_hold of wall time at a time; hold while the device has unread bytes,
at most max_hold in a row.
"""

import pytest

from tactile_sim.clock_gate import ClockGate

DT_S, WALL_DT_S = 2.0**-7, 2.0**-9  # a 128 Hz tick, ~2 ms of wall time per attempt: exact in binary
LAG_S, LAG_HOLD_S = 3 * DT_S, 0.25


def _run(gate: ClockGate, attempts: int, t_s: float = 0.0, backlog: int = 0, wall_s: float = 0.0):
    """Try to tick ``attempts`` times; the simulated time reached and the wall time spent."""
    for _ in range(attempts):
        if not gate.hold(t_s, backlog, wall_s):
            t_s += DT_S
        wall_s += WALL_DT_S
    return t_s, wall_s


def test_without_progress_reports_the_clock_runs_free():
    gate = ClockGate(max_hold_s=2.0, max_lag_s=LAG_S, max_lag_hold_s=LAG_HOLD_S)
    t_s, _ = _run(gate, 100)
    assert t_s == 100 * DT_S and gate.held_ticks == 0


@pytest.mark.parametrize("who", ["driver", "commander"])
def test_the_clock_stops_max_lag_ahead_of_the_slower_of_driver_and_commander(who):
    gate = ClockGate(max_hold_s=2.0, max_lag_s=LAG_S, max_lag_hold_s=LAG_HOLD_S)
    gate.on_decided(1.0)
    gate.on_acted(1.0)
    # The other one keeps up with any clock; the one under test stays at 1.0 s.
    (gate.on_acted if who == "driver" else gate.on_decided)(10.0)
    t_s, _ = _run(gate, 50, t_s=1.0)  # 0.1 s of wall: within one lag hold
    assert t_s == 1.0 + LAG_S + DT_S  # the tick that passes the lag is taken, the next one waits
    assert gate.lag_held_ticks == 50 - 4
    # It catches up: the clock goes on at once.
    (gate.on_decided if who == "driver" else gate.on_acted)(t_s)
    t2_s, _ = _run(gate, 3, t_s=t_s)
    assert t2_s == t_s + 3 * DT_S


def test_a_commander_that_never_reports_does_not_hold_the_clock():
    """A graph without a commander (or one from before /arm/acted_through): the driver alone counts."""
    gate = ClockGate(max_hold_s=2.0, max_lag_s=LAG_S, max_lag_hold_s=LAG_HOLD_S)
    gate.on_decided(5.0)
    t_s, _ = _run(gate, 3, t_s=5.0)
    assert t_s == 5.0 + 3 * DT_S and gate.held_ticks == 0


def test_a_silent_loop_lets_one_tick_through_per_lag_hold():
    """A process that is gone must not stop the rig: after max_lag_hold of wall time one tick passes."""
    gate = ClockGate(max_hold_s=2.0, max_lag_s=LAG_S, max_lag_hold_s=LAG_HOLD_S)
    gate.on_decided(0.0)
    gate.on_acted(0.0)
    t_s, _ = _run(gate, 1000, t_s=4 * DT_S)  # ~2 s of wall time, starting past the lag
    # Each hold lasts while wall - start <= 0.25 s (129 attempts), the next attempt ticks.
    per_tick = int(LAG_HOLD_S / WALL_DT_S) + 2
    assert t_s == (4 + 1000 // per_tick) * DT_S


def test_progress_messages_never_move_backwards():
    gate = ClockGate(max_hold_s=2.0, max_lag_s=LAG_S, max_lag_hold_s=LAG_HOLD_S)
    gate.on_decided(2.0)
    gate.on_decided(1.0)  # an old message delivered late
    gate.on_acted(3.0)
    gate.on_acted(0.5)
    assert gate.through_s() == 2.0


def test_a_backlog_on_the_link_holds_at_most_max_hold_in_a_row():
    gate = ClockGate(max_hold_s=0.125, max_lag_s=LAG_S, max_lag_hold_s=LAG_HOLD_S)
    t_s, _ = _run(gate, 100, backlog=64)  # ~0.2 s of wall with unread bytes
    # Held while wall - start <= 0.125 s (65 attempts), then ticks every attempt.
    assert t_s == (100 - 65) * DT_S


def test_lag_zero_switches_the_sensing_lock_step_off():
    gate = ClockGate(max_hold_s=2.0, max_lag_s=0.0, max_lag_hold_s=0.25)
    gate.on_decided(0.0)
    gate.on_acted(0.0)
    t_s, _ = _run(gate, 20, t_s=1.0)
    assert t_s == 1.0 + 20 * DT_S
