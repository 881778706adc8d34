"""tactile_common.stamps against exact decimal arithmetic."""

from decimal import Decimal

import pytest
from builtin_interfaces.msg import Duration, Time

from tactile_common.stamps import (duration_from_ns, duration_from_s, ns_from_s, stamp_ns, stamp_s, time_from_ns,
                                   time_from_s)

SECONDS = [0.0, 1e-9, 0.5, 0.9999999999, 1.0000000004, 12.345678901, 1_700_000_000.123456, -0.25]


def _exact_ns(t_s: float) -> int:
    """Nearest nanosecond of the float's exact decimal value (ties away from zero never occur here)."""
    return int((Decimal(t_s) * 10**9).to_integral_value())


@pytest.mark.parametrize("t_s", SECONDS)
def test_from_seconds_rounds_to_the_nearest_nanosecond_and_normalises(t_s):
    for msg in (time_from_s(t_s), duration_from_s(t_s)):
        assert 0 <= msg.nanosec < 10**9
        assert msg.sec * 10**9 + msg.nanosec == _exact_ns(t_s)
    assert isinstance(time_from_s(t_s), Time) and isinstance(duration_from_s(t_s), Duration)
    assert ns_from_s(t_s) == _exact_ns(t_s)


def test_a_second_is_not_lost_to_rounding():
    d = duration_from_s(0.9999999999)
    assert (d.sec, d.nanosec) == (1, 0)


@pytest.mark.parametrize("ns", [0, 1, 999_999_999, 10**9, 5 * 10**9 + 7, 1_700_000_000_123_456_789, -1])
def test_nanoseconds_round_trip_exactly(ns):
    assert stamp_ns(time_from_ns(ns)) == ns
    assert stamp_ns(duration_from_ns(ns)) == ns
    msg = time_from_ns(ns)
    assert (msg.sec, msg.nanosec) == (ns // 10**9, ns % 10**9)


def test_stamp_s_of_a_message():
    assert stamp_s(Time(sec=3, nanosec=250_000_000)) == 3.25
    assert stamp_ns(Duration(sec=2, nanosec=5)) == 2_000_000_005


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_seconds_are_refused(bad):
    with pytest.raises(ValueError, match="finite number of seconds"):
        time_from_s(bad)
