"""benchmarks/zoo_survey.py's verdicts and summary (the README's drop_zoo figures come from
them): a campaign is right when every required effect is named and nothing outside `allowed`;
a missed effect the report pointed at as the closest candidate of what it left unexplained is
counted as said, not named."""

from __future__ import annotations

import sys
from argparse import Namespace
from pathlib import Path
from typing import Any

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import zoo_survey  # noqa: E402


def _row(name: str, found: list[str], truth: dict[str, Any], pointed: list[str]) -> dict[str, Any]:
    row = {
        "campaign": name,
        "found": {e: {"parameters": {}, "interval": {}, "on_load_cell": False} for e in found},
        "unexplained": ["impact"] if pointed else [],
        "pointed_at": pointed,
        "seconds": 2.0,
        "truth": truth,
    }
    row["verdict"] = zoo_survey.judge(row, truth)
    return row


def test_missed_effects_pointed_at_are_counted_as_said_not_named() -> None:
    offset = {"required": ["torque_offset", "payload_gravity"], "allowed": ["stiction"],
              "params": {"offset_nm": -0.03}}  # fmt: skip
    free = {"required": ["payload_gravity"], "allowed": ["stiction"], "params": {}}
    rows = [
        # zoo_13118: the offset missed, the report's closest candidate
        _row("a", ["payload_gravity"], offset, ["torque_offset"]),
        # missed and pointed at something else
        _row("b", ["payload_gravity"], offset, ["parameter_drift"]),
        # named: not a miss, whatever else is pointed at
        _row("c", ["payload_gravity", "torque_offset"], offset, ["cogging"]),
        # a stiction named where nothing is hidden is allowed: right
        _row("d", ["payload_gravity", "stiction"], free, []),
    ]
    assert [r["verdict"]["right"] for r in rows] == [False, False, True, True]
    assert rows[0]["verdict"]["missed"] == ["torque_offset"]
    args = Namespace(seeds="1-4", jobs=1, analyse_jobs=1)
    lines = zoo_survey.summary(rows, args, total=10.0, made=1.0)
    assert "| campaigns fully right | 2/4 (50 %) | ≥ 90 % |" in lines
    assert (
        "| effect-free campaigns naming nothing outside `allowed` | 1/1 (100 %) | ≥ 95 % |" in lines
    )
    said = [line for line in lines if line.startswith("Required effects missed")]
    assert said == [
        "Required effects missed: 2; of them 1 given as the closest candidate of a residual "
        "the report leaves unexplained (said, not named)."
    ]
