"""Per-candidate shares of the drop-test decision rule: how benchmarks/share_calibration.py sets
them from logged rounds, that the package ships the calibrated ones, and that the loop judges
each candidate (and a pair) by its own."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.drop import SHARE_NEEDED
from transparency_ros.analysis.discrepancy.steps import Base, Step

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import share_calibration  # noqa: E402


def _step(cand: str, gain: float, *, daic: float = -50.0, names: bool = False) -> dict[str, Any]:
    return {
        "stage": "DropProblem", "before": ["payload_gravity"], "cand": cand, "gain": gain,
        "judged": [1.0, 1.0 - gain, 0.1], "daic": daic, "meaningful": True, "null_in": False,
        "names": names, "params": [0.0], "after_search": False,
    }  # fmt: skip


def _row(name: str, steps: list[dict[str, Any]], required: list[str]) -> dict[str, Any]:
    truth = {"required": ["payload_gravity", *required], "allowed": [], "params": {}}
    return {"campaign": name, "found": [], "declared": ["payload_gravity"], "steps": steps,
            "truth": truth}  # fmt: skip


def test_a_share_is_the_least_that_names_the_effect_in_at_most_one_campaign_in_a_hundred() -> None:
    """100 campaigns without a cogging: it would have been named at 0.62 in one and 0.66 in
    another, so 0.60 names it in 2 (> 1 %), 0.65 in one: its share is 0.65. A delay never
    decisive where absent gets the least share, 0.5."""
    steps = [_step("cogging", 0.3), _step("sensor_delay", 0.2)]
    rows = [_row(f"zoo_{k}", steps, []) for k in range(98)]
    rows += [
        _row("zoo_a", [_step("cogging", 0.62)], []),
        _row("zoo_b", [_step("cogging", 0.66)], []),
    ]
    rows += [_row("zoo_h", [_step("cogging", 0.7)], ["cogging"])]
    _lines, data = share_calibration.table(rows)
    cogging = data["candidates"]["cogging"]
    assert cogging["share"] == 0.65
    assert cogging["absent_campaigns"] == 100 and cogging["hidden_campaigns"] == 1
    assert cogging["named_where_absent"]["0.6"] == 2 and cogging["named_where_hidden"]["0.7"] == 1
    assert data["candidates"]["sensor_delay"]["share"] == 0.5


def test_what_no_share_refuses_does_not_count_and_few_campaigns_keep_the_uniform_share() -> None:
    """A drift named falsely at 0.97 (it stood in for all the error there) counts against no
    share: with two more at 0.70 and 0.72 in 100 campaigns, 0.75 names one (the 0.97), and
    that is its share. A spring absent from 30 campaigns only keeps the uniform 0.75."""
    rows = [_row(f"zoo_{k}", [_step("parameter_drift", 0.2)], []) for k in range(97)]
    rows += [_row(f"zoo_d{g}", [_step("parameter_drift", g)], []) for g in (0.97, 0.7, 0.72)]
    assert share_calibration.table(rows)[1]["candidates"]["parameter_drift"]["share"] == 0.75
    rows = [_row(f"zoo_s{k}", [_step("structural_compliance", 0.3)], []) for k in range(30)]
    spring = share_calibration.table(rows)[1]["candidates"]["structural_compliance"]
    assert spring["share"] == share_calibration.UNIFORM


def test_a_step_that_would_not_have_been_chosen_is_not_decisive() -> None:
    """A cogging removing 0.7 in a round where a spring was named with a better information
    criterion would not have been named whatever its share; nor one that misses the criterion
    or whose interval holds its null."""
    steps = [
        _step("cogging", 0.7, daic=-40),
        _step("structural_compliance", 0.9, daic=-90, names=True),
    ]
    assert "cogging" not in share_calibration.decisive(_row("zoo_1", steps, []))
    alone = [_step("cogging", 0.7, daic=-5)]
    assert "cogging" not in share_calibration.decisive(_row("zoo_2", alone, []))
    held = [{**_step("cogging", 0.7), "null_in": True}]
    assert "cogging" not in share_calibration.decisive(_row("zoo_3", held, []))
    assert share_calibration.decisive(_row("zoo_4", [_step("cogging", 0.7)], [])) == {
        "cogging": 0.7
    }


def test_the_package_ships_the_calibrated_shares() -> None:
    calibrated = json.loads((BENCHMARKS / "results" / "share_calibration.json").read_text())
    assert {c: p["share"] for c, p in calibrated["candidates"].items()} == SHARE_NEEDED


def _loop(shares: dict[str, float] | None, given: float | None = None) -> Discoverer:
    problem = SimpleNamespace(min_improvement=0.75)
    if shares is not None:
        problem.share_needed = lambda effect: shares.get(effect.name, 0.75)
    return Discoverer(problem, min_improvement=given)  # type: ignore[arg-type]


def _named(loop: Discoverer, added: list[str], gain: float) -> bool:
    after = 1.0 - gain * 0.9
    step = Step(
        added=[SimpleNamespace(name=n, declared=n == "payload_gravity") for n in added],
        params=[np.zeros(1)] * len(added),
        err=np.full(1000, after),
        rmse=after,
        aic=1000 * np.log(after**2),
        gain=gain,
        judged=(1.0, after, 0.1),
        result=None,
        meaningful=True,
    )
    base = Base(np.ones(1000), 1.0, 0.0, 0.1)
    return loop._names(step, base)


@pytest.mark.parametrize(
    ("added", "gain", "named"),
    [
        (["cogging"], 0.6, True),  # its own share, 0.55
        (["backlash"], 0.6, False),  # a candidate the table does not list: 0.75
        (["cogging", "backlash"], 0.7, False),  # a pair: the stricter of its members'
        (["cogging", "backlash"], 0.8, True),
        (["cogging", "payload_gravity"], 0.6, True),  # the declared weight: nothing fitted
    ],
)
def test_each_candidate_is_judged_by_its_own_share(
    added: list[str], gain: float, named: bool
) -> None:
    assert _named(_loop({"cogging": 0.55}), added, gain) is named


def test_a_share_given_to_the_loop_holds_for_every_candidate() -> None:
    """A share given to the loop (min_improvement) overrides the problem's table; a problem
    without one (the torque-driven recordings) is judged by its min_improvement."""
    assert not _named(_loop({"cogging": 0.55}, given=0.75), ["cogging"], 0.6)
    assert not _named(_loop(None), ["cogging"], 0.6)
    assert _named(_loop(None), ["cogging"], 0.8)
