"""Percentiles of a duration over any number of samples, in fixed memory.

Durations are counted in log-spaced bins (1 % wide from 1 us to 1000 s, 2085 bins), so a
percentile is exact to within 1 % of its value however long a node runs. The maximum is kept
exactly, and stands for percentiles beyond 1000 s (such as the age of a replayed bag's
samples). Adding a sample costs about 1.5 us. The estimator uses it for its handler's time and
for the sample age (how long after the source stamped a sample its outputs went out).
"""

from __future__ import annotations

import math
from array import array

import numpy as np

LOW_S = 1e-6
HIGH_S = 1e3
RATIO = 1.01
_LOG_RATIO = math.log(RATIO)
N_BINS = math.ceil(math.log(HIGH_S / LOW_S) / _LOG_RATIO) + 2  # below LOW_S, ..., beyond HIGH_S


class DurationHistogram:
    """Counts of durations [s]; negative ones (a stamp from the future) are counted apart."""

    def __init__(self) -> None:
        self.counts = array("q", bytes(8 * N_BINS))  # int64; adding is cheaper than numpy's
        self.count = self.negative = 0
        self.max_s = math.nan

    def copy(self) -> DurationHistogram:
        """A snapshot (a few microseconds: take it under a lock, compute percentiles after)."""
        other = DurationHistogram()
        other.counts = array("q", self.counts)
        other.count, other.negative, other.max_s = self.count, self.negative, self.max_s
        return other

    def add(self, seconds: float) -> None:
        if not seconds >= 0.0:  # also NaN
            self.negative += 1
            return
        index = int(math.log(seconds / LOW_S) / _LOG_RATIO) + 1 if seconds >= LOW_S else 0
        self.counts[min(index, N_BINS - 1)] += 1
        self.count += 1
        if not seconds <= self.max_s:
            self.max_s = seconds

    def percentile(self, q: float) -> float:
        """The q-th percentile [s] (0 <= q <= 100), as its bin's geometric centre; NaN if empty."""
        if not self.count:
            return math.nan
        cumulative = np.cumsum(np.frombuffer(self.counts, dtype=np.int64))
        index = int(np.searchsorted(cumulative, max(1, math.ceil(q / 100.0 * self.count))))
        if index == 0:
            return float(min(LOW_S / 2, self.max_s))
        if index == N_BINS - 1:  # off the scale (beyond HIGH_S): the largest is all we know
            return self.max_s
        centre = LOW_S * RATIO ** (index - 0.5)
        return float(min(centre, self.max_s))

    def reset(self) -> None:
        self.counts = array("q", bytes(8 * N_BINS))
        self.count = self.negative = 0
        self.max_s = math.nan
