"""Message <-> core value conversions shared by the nodes.

Stamps cross into the core as integer nanoseconds (``stamp_to_ns``) and come back out with
``ns_to_stamp``: exact both ways, for any stamp a ``builtin_interfaces/Time`` holds. Float
seconds (``stamp_to_s``) are for durations and display only: at today's epoch (1.8e9 s) a
float64 resolves about 240 ns, so a stamp rounded through it no longer matches its sample.
"""

from __future__ import annotations

from builtin_interfaces.msg import Time

from transparency_ros.core import stamps
from transparency_ros.core.stamps import from_seconds as s_to_ns

__all__ = ["ns_to_stamp", "s_to_ns", "stamp_to_ns", "stamp_to_s"]


def stamp_to_ns(stamp: Time) -> int:
    """A header stamp as integer nanoseconds (exact)."""
    return stamps.join(stamp.sec, stamp.nanosec)


def ns_to_stamp(stamp_ns: int) -> Time:
    """Integer nanoseconds as a header stamp (exact; negative stamps borrow from sec)."""
    sec, nanosec = stamps.split(stamp_ns)
    return Time(sec=sec, nanosec=nanosec)


def stamp_to_s(stamp: Time) -> float:
    """A header stamp as seconds (float: for durations and display, not for matching stamps)."""
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9
