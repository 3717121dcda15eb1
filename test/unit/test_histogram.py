"""core.histogram: percentiles within 1 % of numpy's on the same samples, in fixed memory."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from transparency_ros.core.histogram import HIGH_S, N_BINS, DurationHistogram

durations = st.floats(min_value=2e-6, max_value=HIGH_S / 2)


@settings(max_examples=200, deadline=None)
@given(st.lists(durations, min_size=1, max_size=300), st.sampled_from([1, 50, 90, 99, 100]))
def test_percentiles_within_one_percent_of_numpy(values: list[float], q: float) -> None:
    hist = DurationHistogram()
    for v in values:
        hist.add(v)
    exact = float(np.percentile(values, q, method="inverted_cdf"))
    assert hist.percentile(q) == np.float64(exact) or abs(hist.percentile(q) / exact - 1) <= 0.005
    assert hist.max_s == max(values) and hist.count == len(values)


def test_edges_negative_and_off_scale() -> None:
    hist = DurationHistogram()
    assert math.isnan(hist.percentile(50))
    for v in (-1e-3, math.nan, 0.0, 5e-7, 2e3):
        hist.add(v)
    assert hist.negative == 2 and hist.count == 3 and len(hist.counts) == N_BINS
    assert hist.percentile(1) == 5e-7  # below 1 us: 0.5 us (or the largest, if smaller)
    assert hist.percentile(100) == 2e3  # beyond the scale: the largest
    copy = hist.copy()
    hist.reset()
    assert hist.count == hist.negative == 0 and sum(hist.counts) == 0
    assert copy.percentile(100) == 2e3 and copy.count == 3 and copy.negative == 2
