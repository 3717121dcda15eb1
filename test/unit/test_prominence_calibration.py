"""Cogging's period prominence on logged zoo campaigns, as benchmarks/prominence_calibration.py
tables it: which campaigns a waived share would name a wave in, with and without a hidden one."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import prominence_calibration  # noqa: E402


def _step(
    periods: int,
    prominence: float,
    cycles: float,
    *,
    eligible: bool = True,
    spread: float | None = None,
    independent: float | None = 20.0,
) -> dict[str, Any]:
    return {
        "stage": "ForceView", "before": ["payload_gravity"], "periods": periods,
        "amplitude_nm": 0.04, "prominence": prominence, "cycles": cycles, "gain": 0.5,
        "eligible": eligible, "names": False, "spread": spread, "independent": independent,
    }  # fmt: skip


def _row(name: str, steps: list[dict[str, Any]], periods: int | None) -> dict[str, Any]:
    hidden = periods is not None
    truth = {
        "required": ["payload_gravity", *(["cogging"] if hidden else [])],
        "allowed": ["stiction"],
        "params": {"cogging_periods_per_rev": periods} if hidden else {},
    }
    return {"campaign": name, "found": [], "steps": steps, "truth": truth}


def test_a_threshold_counts_absent_campaigns_and_hidden_ones_at_their_true_period() -> None:
    """Scans that told 20 periods apart (a threshold of log2(20 / 0.01) = 10.97). Absent: a
    wave of prominence 9 over 5 periods of travel (0.82 of its threshold) counts from 0.8
    down, and from a flat 8 down; one of 40 over a single period (a smooth torque) and an
    ineligible one of 50 never. Hidden (N = 100): a prominence of 20 at N = 102 (within 3 %;
    1.82 of its threshold) counts up to 1.5 and to a flat 20; one of 60 at N = 140 (a wrong
    period) never."""
    from transparency_ros.analysis.discrepancy.steps import prominent_wave  # noqa: PLC0415

    rows = [
        _row("zoo_1", [_step(30, 9.0, 5.0)], None),
        _row("zoo_2", [_step(12, 40.0, 1.0), _step(80, 50.0, 6.0, eligible=False)], None),
        _row("zoo_3", [_step(102, 20.0, 7.0)], 100),
        _row("zoo_4", [_step(140, 60.0, 9.0)], 100),
    ]
    _lines, data = prominence_calibration.table(rows)
    assert (data["absent"], data["hidden"]) == (2, 2)
    waived, flat = data["waived"], data["flat"]
    assert waived["0.8"] == {"absent_named": 1, "hidden_named": 1}
    assert waived["0.9"] == {"absent_named": 0, "hidden_named": 1}
    assert waived["2.0"] == {"absent_named": 0, "hidden_named": 0}
    assert flat["8.0"] == {"absent_named": 1, "hidden_named": 1}
    assert flat["10.0"] == {"absent_named": 0, "hidden_named": 1}
    assert flat["30.0"] == {"absent_named": 0, "hidden_named": 0}
    assert data["absent_largest"] == [9.0 / prominent_wave(20.0), 0.0]
    assert data["hidden_true_largest"] == [20.0 / prominent_wave(20.0), 0.0]


def test_a_step_logged_before_its_scan_counted_its_periods_gets_them_from_its_travel() -> None:
    """N = 100 over 5 periods of travel: 0.314 rad; the scan's range 20 (one period over the
    travel) to 400 over its resolution 2 pi / 0.314 is 19 periods told apart."""
    old = _step(100, 12.0, 5.0, independent=None)
    assert prominence_calibration.independent(old) == 19.0
    assert prominence_calibration.independent(_step(100, 12.0, 5.0)) == 20.0


def test_the_spread_table_counts_waves_every_trial_shows_alike_over_enough_periods() -> None:
    """Absent: a spread of 0.25 over 1.8 periods of travel (a smooth torque) is banded but
    never counts; one of 0.7 over 4 periods counts from 0.8 up. Hidden (N = 100): 0.3 at N =
    101 counts from 0.3 up; 0.1 at a wrong period (N = 150) never. A campaign logged before
    the spread was measured is left out."""
    rows = [
        _row("zoo_1", [_step(30, 2.0, 1.8, spread=0.25), _step(60, 2.0, 4.0, spread=0.7)], None),
        _row("zoo_2", [_step(101, 2.0, 5.0, spread=0.3), _step(150, 2.0, 7.0, spread=0.1)], 100),
        _row("zoo_3", [{k: v for k, v in _step(40, 2.0, 5.0).items() if k != "spread"}], None),
    ]
    _lines, data = prominence_calibration.table(rows)
    spread = data["spread"]
    assert spread["measured"] == 2
    assert spread["named"]["0.6"] == {"absent_named": 0, "hidden_named": 1}
    assert spread["named"]["0.8"] == {"absent_named": 1, "hidden_named": 1}
    assert spread["named"]["0.2"] == {"absent_named": 0, "hidden_named": 0}
    first, _middle, last = spread["bands"]
    assert first["absent_least"] == [0.25] and first["hidden_true"] == []
    assert last["absent_least"] == [0.7] and last["hidden_true"] == [0.3]
