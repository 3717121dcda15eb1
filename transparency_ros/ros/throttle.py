"""A warning logged at most once per period (a bad stream at 1 kHz must not flood the log)."""

from __future__ import annotations

import math
import time
from typing import Any


class ThrottledWarning:
    """``warn(text)``: log ``text`` as a warning unless one was logged less than ``period_s``
    ago (the ones in between are dropped; counters say how many there were)."""

    def __init__(self, logger: Any, period_s: float = 1.0) -> None:
        self.logger, self.period_s = logger, period_s
        self._last_s = -math.inf

    def __call__(self, text: str) -> None:
        now = time.monotonic()
        if now - self._last_s >= self.period_s:
            self._last_s = now
            self.logger.warning(text)
