"""How long the garbage collector stops this process: every collection timed, in fixed memory.

A full collection holds the interpreter lock; every thread of the process, the driver's
hardware loop among them, waits for it. :class:`GcPauses` times each collection through
``gc.callbacks`` (about 1 us per collection) so that a stall of the loop can be told apart from
one of the scheduler or of another thread holding the lock. Time is read with
``time.perf_counter`` here: this module measures the host itself, it computes nothing.
"""

from __future__ import annotations

import gc
import time
from typing import Any

from transparency_ros.core.histogram import DurationHistogram


class GcPauses:
    """Durations of this process's collections (all generations), from :meth:`start` on."""

    def __init__(self) -> None:
        self.durations = DurationHistogram()
        self.full = 0  # generation-2 collections
        self._began = 0.0

    def _callback(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._began = time.perf_counter()
            return
        self.durations.add(time.perf_counter() - self._began)
        if info.get("generation") == 2:
            self.full += 1

    def start(self) -> GcPauses:
        if self._callback not in gc.callbacks:
            gc.callbacks.append(self._callback)
        return self

    def stop(self) -> None:
        if self._callback in gc.callbacks:
            gc.callbacks.remove(self._callback)
