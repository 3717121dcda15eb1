"""Message <-> core value conversions shared by the nodes."""

from __future__ import annotations

import math

from builtin_interfaces.msg import Time


def stamp_to_s(stamp: Time) -> float:
    """A header stamp as seconds (float)."""
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def s_to_stamp(seconds: float) -> Time:
    """Seconds as a header stamp, nanoseconds rounded (never 1e9)."""
    sec = math.floor(seconds)
    nanosec = round((seconds - sec) * 1e9)
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return Time(sec=int(sec), nanosec=int(nanosec))
