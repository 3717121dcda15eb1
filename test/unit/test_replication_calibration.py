"""The replication spread of any single effect and its table, as
benchmarks/replication_calibration.py measures them (tried as a waiver of the drop-test
share and as a refusal; kept as neither: docs/discrepancy.md)."""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import replication_calibration as rc  # noqa: E402


class _Linear:
    """Trials whose error is (a_i - x) g_i for an effect of size x (a stand-in problem, linear
    so that the spread is known exactly): a_i the size each trial shows."""

    def __init__(self, fit: Sequence[float], held: Sequence[float]) -> None:
        t = np.linspace(0.0, 1.0, 50)
        self.shape = np.sin(7 * t) + t
        self.sizes = {False: list(fit), True: list(held)}

    def error_sets(
        self, effects: Sequence[Any], sets: Sequence[Sequence[Any]], held: bool
    ) -> list[Any]:
        out = []
        for params in sets:
            x = float(params[-1][0]) if effects else 0.0
            out.append(np.concatenate([(a - x) * self.shape for a in self.sizes[held]]))
        return out

    def trial_index(self, held: bool) -> Any:
        return np.repeat(np.arange(len(self.sizes[held])), self.shape.size)


def _effect(null: tuple[float, ...] | None = (0.0,), fittable: bool = True) -> Any:
    return SimpleNamespace(lower=(-10.0,), upper=(10.0,), null=null, fittable=fittable)


@pytest.mark.parametrize("null", [(0.0,), None])
def test_the_spread_is_what_each_trial_would_change_over_what_the_effect_does(
    null: tuple[float, ...] | None,
) -> None:
    """Every trial showing the fitted size: 0. Trials showing 1 and 3 where 2 is fitted: each
    would move the model by 1 g where the effect does 2 g, 0.5. The same where the effect has
    no null value (its contribution is then the model without it)."""
    alike = _Linear([2.0, 2.0, 2.0], [2.0])
    assert rc.spread_of(alike, [], [np.array([2.0])], _effect(null)) == pytest.approx(0, abs=1e-9)
    apart = _Linear([1.0, 3.0], [3.0, 1.0])
    assert rc.spread_of(apart, [], [np.array([2.0])], _effect(null)) == pytest.approx(0.5)
    # a trial far off counts at most CAP times the effect
    far = _Linear([2.0, 2.0 + 2.0 * 10], [2.0])
    assert rc.spread_of(far, [], [np.array([2.0])], _effect(null)) == pytest.approx(rc.CAP / 3)


def test_no_spread_where_nothing_is_fitted_or_trials_are_not_told_apart() -> None:
    problem = _Linear([1.0, 3.0], [2.0])
    assert math.isnan(rc.spread_of(problem, [], [np.array([2.0])], _effect(fittable=False)))
    # a problem that does not say which trial each element is of (a load cell's bins)
    pooled = SimpleNamespace(error_sets=problem.error_sets)
    assert math.isnan(rc.spread_of(pooled, [], [np.array([2.0])], _effect()))


def _step(cand: str, gain: float, spread: float | None, *, names: bool = False) -> dict[str, Any]:
    return {"stage": "DropProblem", "before": ["payload_gravity"], "cand": cand, "gain": gain,
            "needed": 0.75, "names": names, "params": [0.0], "spread": spread}  # fmt: skip


def test_the_table_counts_waived_and_refused_effects_against_the_truth() -> None:
    """zoo_1 hides an offset, refused at 0.68 with a spread of 0.04, and a drift not hidden
    was refused at 0.5 with 0.01: as a waiver at 0.05 both are named (one required, one
    neither). zoo_2 names its hidden drift with 0.3 (refused above 0.2, not above 0.3) and an
    allowed rebound with 0.01; an offset refused with 0.5 is never waived, and a step
    without a spread is not counted."""
    rows = [
        {"campaign": "zoo_1", "found": ["payload_gravity"], "declared": ["payload_gravity"],
         "steps": [_step("torque_offset", 0.68, 0.04), _step("torque_offset", 0.6, 0.2),
                   _step("parameter_drift", 0.5, 0.01)],
         "truth": {"required": ["payload_gravity", "torque_offset"], "allowed": []}},
        {"campaign": "zoo_2", "found": ["payload_gravity", "parameter_drift", "restitution"],
         "declared": ["payload_gravity"],
         "steps": [_step("parameter_drift", 0.9, 0.3, names=True),
                   _step("parameter_drift", 0.95, 0.01, names=True),
                   _step("restitution", 0.8, 0.01, names=True),
                   _step("torque_offset", 0.4, 0.5), _step("cogging", 0.3, None)],
         "truth": {"required": ["payload_gravity", "parameter_drift"],
                   "allowed": ["restitution"]}},
    ]  # fmt: skip
    lines, data = rc.table(rows)
    assert data["in_band"] == {"required": 1, "allowed": 0, "neither": 2}
    assert data["waiver"]["0.02"] == {"required": 0, "allowed": 0, "neither": 1}
    assert data["waiver"]["0.05"] == {"required": 1, "allowed": 0, "neither": 1}
    assert data["waiver"]["0.3"] == {"required": 1, "allowed": 0, "neither": 1}
    assert data["named"] == {"required": 1, "allowed": 1, "neither": 0}
    assert data["refusal"]["0.2"] == {"required": 1, "allowed": 0, "neither": 0}
    assert data["refusal"]["0.3"] == {"required": 0, "allowed": 0, "neither": 0}
    assert "| 0.05 | 1 | 0 | 1 |" in lines
