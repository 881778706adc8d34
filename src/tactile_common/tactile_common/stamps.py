"""builtin_interfaces Time/Duration <-> integers and floats (one place for the arithmetic)."""

from __future__ import annotations

from builtin_interfaces.msg import Time


def stamp_ns(stamp) -> int:
    """Nanoseconds of a Time or Duration message (exact)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def stamp_s(stamp) -> float:
    """Seconds of a Time or Duration message."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def time_from_ns(ns: int) -> Time:
    """A Time message of ``ns`` nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)
