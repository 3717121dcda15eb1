"""Stamps as integer nanoseconds: the one place their arithmetic is written.

A header stamp (sec, nanosec) is kept as ``sec * 1e9 + nanosec`` wherever it is stored or
compared: exact for every stamp a ``builtin_interfaces/Time`` holds. Float seconds resolve only
about 240 ns at today's epoch (1.8e9 s); they appear as differences and for display.
"""

from __future__ import annotations

import math

NS_PER_S = 1_000_000_000


def join(sec: int, nanosec: int) -> int:
    """(sec, nanosec) as integer nanoseconds."""
    return int(sec) * NS_PER_S + int(nanosec)


def split(stamp_ns: int) -> tuple[int, int]:
    """Integer nanoseconds as (sec, nanosec), nanosec in [0, 1e9) (negative stamps borrow)."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return sec, nanosec


def text(stamp_ns: int) -> str:
    """Exact seconds text, ``sec.nanosec``."""
    sec, nanosec = split(stamp_ns)
    return f"{sec}.{nanosec:09d}"


def from_seconds(seconds: float) -> int:
    """Where a stamp is made from a clock that reads float seconds (python-can's bus time):
    whole seconds kept exact, the fraction rounded to the nanosecond."""
    sec = math.floor(seconds)
    return int(sec) * NS_PER_S + round((seconds - sec) * 1e9)
