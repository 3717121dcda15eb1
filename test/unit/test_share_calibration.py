"""Per-candidate shares of the drop-test decision rule, as benchmarks/share_calibration.py sets
them from logged rounds (the package keeps one share: on fresh seeds the calibrated ones lost
more campaigns than they mended, docs/discrepancy.md)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

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
    assert cogging["rate_share"] == 0.65
    assert cogging["absent_campaigns"] == 100 and cogging["hidden_campaigns"] == 1
    assert cogging["named_where_absent"]["0.6"] == 2 and cogging["change"]["0.7"] == [1, 0]
    assert data["candidates"]["sensor_delay"]["rate_share"] == 0.5


def test_what_no_share_refuses_does_not_count_and_few_campaigns_keep_the_uniform_share() -> None:
    """A drift named falsely at 0.97 (it stood in for all the error there) counts against no
    share: with two more at 0.70 and 0.72 in 100 campaigns, 0.75 names one (the 0.97), and
    that is its share. A spring absent from 30 campaigns only keeps the uniform 0.75."""
    rows = [_row(f"zoo_{k}", [_step("parameter_drift", 0.2)], []) for k in range(97)]
    rows += [_row(f"zoo_d{g}", [_step("parameter_drift", g)], []) for g in (0.97, 0.7, 0.72)]
    assert share_calibration.table(rows)[1]["candidates"]["parameter_drift"]["rate_share"] == 0.75
    rows = [_row(f"zoo_s{k}", [_step("structural_compliance", 0.3)], []) for k in range(30)]
    spring = share_calibration.table(rows)[1]["candidates"]["structural_compliance"]
    assert spring["rate_share"] == share_calibration.UNIFORM


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


def test_a_share_is_weighed_by_the_campaigns_it_mends_against_those_it_loses() -> None:
    """Lowering a delay's share to 0.6 mends two campaigns whose hidden delay removed 0.62 and
    0.7 and was not named, and names one falsely (0.65 where absent); one named already
    (found) is neither. Raising it to 0.85 loses a hidden delay named at 0.8 and mends a
    false one named at 0.78. The balanced share is 0.7 (+1 / -0): as good as 0.5-0.6 (+2 / -1),
    and nearer the uniform share."""
    rows = [
        _row("zoo_1", [_step("sensor_delay", 0.62)], ["sensor_delay"]),
        _row("zoo_2", [_step("sensor_delay", 0.7)], ["sensor_delay"]),
        _row("zoo_3", [_step("sensor_delay", 0.65)], []),
        {**_row("zoo_4", [_step("sensor_delay", 0.68)], []), "found": ["sensor_delay"]},
        {
            **_row("zoo_5", [_step("sensor_delay", 0.8)], ["sensor_delay"]),
            "found": ["sensor_delay"],
        },
        {**_row("zoo_6", [_step("sensor_delay", 0.78)], []), "found": ["sensor_delay"]},
    ]
    verdicts = share_calibration._verdicts(rows, "sensor_delay")
    assert share_calibration.changed(verdicts, 0.6) == (2, 1)
    assert share_calibration.changed(verdicts, 0.85) == (1, 1)
    assert share_calibration.changed(verdicts, share_calibration.UNIFORM) == (0, 0)
    delay = share_calibration.table(rows)[1]["candidates"]["sensor_delay"]
    assert delay["best_share"] == 0.7 and delay["best_share_change"] == [1, 0]
