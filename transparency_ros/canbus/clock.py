"""The offset between two clocks, measured so that a preempted thread does not corrupt it.

Reading clock A, then clock B, and subtracting is wrong by however long the thread was preempted
between the reads; with several Python threads that is often milliseconds. :class:`ClockOffset`
takes the best of a few bracketed readings (the B reading whose A-bracket is shortest) and
refreshes it every ``refresh_s``, so conversions in between share one offset. Used for
monotonic -> wall (CAN frame timestamps) and monotonic -> ROS time (message stamps).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable


class ClockOffset:
    def __init__(
        self,
        target_now_s: Callable[[], float],
        source_now_s: Callable[[], float] = time.monotonic,
        refresh_s: float = 1.0,
    ) -> None:
        self.target_now_s, self.source_now_s, self.refresh_s = target_now_s, source_now_s, refresh_s
        self._offset_s = 0.0
        self._measured_at = -math.inf
        self._lock = threading.Lock()

    def measure(self, tries: int = 5) -> float:
        """target - source, from the reading with the shortest bracket."""
        best_width, best = math.inf, 0.0
        for _ in range(tries):
            before = self.source_now_s()
            target = self.target_now_s()
            after = self.source_now_s()
            if after - before < best_width:
                best_width, best = after - before, target - 0.5 * (before + after)
        return best

    def offset_s(self) -> float:
        now = self.source_now_s()
        with self._lock:
            if now - self._measured_at >= self.refresh_s:
                self._offset_s, self._measured_at = self.measure(), now
            return self._offset_s

    def __call__(self, source_s: float) -> float:
        """A source-clock instant on the target clock."""
        return source_s + self.offset_s()

    def back(self, target_s: float) -> float:
        """A target-clock instant on the source clock."""
        return target_s - self.offset_s()


WALL = ClockOffset(time.time)  # time.monotonic() -> time.time(), for bus timestamps
