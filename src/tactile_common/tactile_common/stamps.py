"""builtin_interfaces Time/Duration <-> integers and floats (one place for the arithmetic).

A stamp is (sec, nanosec) with 0 ≤ nanosec < 10⁹; floats in seconds are
rounded to the nearest nanosecond, so a second is never lost to rounding
(0.9999999999 s is 1 s, 0 ns).
"""

from __future__ import annotations

import math

from builtin_interfaces.msg import Duration, Time

NS_PER_S = 1_000_000_000


def stamp_ns(stamp) -> int:
    """Nanoseconds of a Time or Duration message (exact)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def stamp_s(stamp) -> float:
    """Seconds of a Time or Duration message."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def _split_ns(ns: int) -> tuple[int, int]:
    return divmod(int(ns), NS_PER_S)


def ns_from_s(t_s: float) -> int:
    """Integer nanoseconds of ``t_s`` seconds (nearest; exact for epoch-sized times)."""
    if not math.isfinite(t_s):
        raise ValueError(f"time must be a finite number of seconds; got {t_s}")
    sec = math.floor(t_s)  # t_s − sec is exact: no precision lost at epoch-sized times
    return int(sec) * NS_PER_S + int(round((t_s - sec) * 1e9))


def time_from_ns(ns: int) -> Time:
    """A Time message of ``ns`` nanoseconds."""
    sec, nanosec = _split_ns(ns)
    return Time(sec=sec, nanosec=nanosec)


def time_from_s(t_s: float) -> Time:
    """A Time message of ``t_s`` seconds (nearest nanosecond)."""
    return time_from_ns(ns_from_s(t_s))


def duration_from_ns(ns: int) -> Duration:
    """A Duration message of ``ns`` nanoseconds."""
    sec, nanosec = _split_ns(ns)
    return Duration(sec=sec, nanosec=nanosec)


def duration_from_s(t_s: float) -> Duration:
    """A Duration message of ``t_s`` seconds (nearest nanosecond)."""
    return duration_from_ns(ns_from_s(t_s))
