"""Cogging's period prominence on the zoo: the statistic and the rule's threshold.

    .venv/bin/python benchmarks/prominence_calibration.py log --zoo DIR --seeds 10900-10999 \
        --log LOG.jsonl [--jobs N]
    .venv/bin/python benchmarks/prominence_calibration.py table LOG.jsonl[.gz]... [--out DIR]

results/prominence_calibration.md comes from ``table
benchmarks/results/prominence_calibration/*.jsonl.gz``.

A cogging's period is chosen among every period the recording can show (``DropCogging.scan``),
so the best of a few hundred waves removes some of any error. Its *prominence* is what the
chosen period's waves remove (the scan's linear fit) against what the median period removes:
a periodogram's peak against its level. A cogging that is there repeats with the position at
its period and no other; an error that is something else (a contact or friction law the
model lacks, a drift) is removed about as well by many periods, or by the coarsest (under two
periods over the arm's travel, a wave is a smooth torque). On the zoo's development campaigns
a cogging the share rule missed (``Discoverer._names``: 0.75 of the error above the noise
floor) had been found by the scan, period and size right, removing 0.45-0.5 of the error
beside the model's own error elsewhere.

``log`` runs the tool on drop_zoo campaigns (``../shared/plants/drop_zoo.py``, made beforehand)
and writes every cogging step (each round, each stage: kinematics, load cell) with the
campaign's truth: JSON lines, one per campaign, appended. ``table`` reads such logs. A step is
*eligible* where every condition of the rule holds but the share (its fit meaningful, its
interval off its null, a tenth of the floor removed, the held-out information criterion
better by 10). Per threshold it counts, over eligible steps: campaigns where cogging is absent
(neither required nor allowed by the answers) that would name it, and campaigns hiding one
where the true period (within 3 %) would be named.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

PROMINENCES = [2.0, 3.0, 5.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0]  # flat thresholds
RATIOS = [0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.5, 2.0]  # prominence over prominent_wave(M)
PERIOD_TOLERANCE = 0.03  # a period this close to the truth is the hidden one
CYCLE_BANDS = [(1.0, 1.25), (1.25, 1.5), (1.5, 2.0), (2.0, float("inf"))]
SPREADS = [0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0]
SPREAD_BANDS = [(1.5, 2.0), (2.0, 2.5), (2.5, float("inf"))]


def log_campaign(campaign: Path) -> dict[str, Any]:
    """The tool on one campaign, every cogging step recorded."""
    from share_calibration import logged_run  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy.steps import null_inside  # noqa: PLC0415

    def record(loop: Any, s: Any, base: Any, cand: Any, _kw: Any) -> Any:
        if not s.scanned:
            return None
        before, after, floor = s.judged
        return {
            "stage": type(loop.problem).__name__,
            "before": [e.name for e in base.effects],
            "periods": int(cand.periods),
            "amplitude_nm": float(s.params[-1][0]),
            "prominence": s.scanned[0][0],
            "cycles": s.scanned[0][1],
            # (NaN, not measured: null, strict JSON)
            "spread": None if math.isnan(s.scanned[0][2]) else s.scanned[0][2],
            "independent": s.scanned[0][3],
            "gain": float(s.gain),
            # every condition of the rule but the share
            "eligible": bool(
                s.meaningful
                and not null_inside(s)
                and before - after >= 0.1 * floor
                and s.aic < base.aic - 10
            ),
            "names": bool(loop._names(s, base)),
        }

    found, _declared, steps = logged_run(campaign, record)
    return {"campaign": campaign.name, "found": found, "steps": steps}


def _kind(truth: dict[str, Any]) -> str:
    if "cogging" in truth["required"]:
        return "hidden"
    return "" if "cogging" in truth["allowed"] else "absent"


def _eligible(
    r: dict[str, Any], band: tuple[float, float], *, true: bool = False
) -> list[dict[str, Any]]:
    """The eligible steps of campaign ``r`` over ``band`` periods of travel (of the true
    period only: ``true``)."""
    return [
        s
        for s in r["steps"]
        if s["eligible"]
        and band[0] <= s["cycles"] < band[1]
        and (not true or _true_period(s, r["truth"]))
    ]


def independent(step: dict[str, Any]) -> float:
    """The periods the step's scan could tell apart (``DropCogging.independent_periods``);
    logs made before it was recorded: from the chosen period and its periods of travel, as
    the scan counts them with its finest period at MOST_COGGING_PERIODS (a coarse encoder's
    is finer than that from 2^12 counts per revolution up; a coarser one's, 2^9-2^11, is
    overstated there, and so its threshold)."""
    if step.get("independent") is not None:
        return float(step["independent"])
    from transparency_ros.analysis.discrepancy.drop_cogging import (  # noqa: PLC0415
        MOST_COGGING_PERIODS,
    )

    span = step["cycles"] * 2 * math.pi / step["periods"] if step["periods"] else 0.0
    if span <= 0.0:
        return 1.0
    coarsest = max(2, math.ceil(2 * math.pi / span))
    return max(1.0, (max(MOST_COGGING_PERIODS, coarsest) - coarsest) * span / (2 * math.pi))


def over_threshold(step: dict[str, Any]) -> float:
    """The step's prominence over the one the rule asks of its scan (1: just named)."""
    from transparency_ros.analysis.discrepancy.steps import prominent_wave  # noqa: PLC0415

    return float(step["prominence"]) / prominent_wave(independent(step))


def _true_period(step: dict[str, Any], truth: dict[str, Any]) -> bool:
    true = truth["params"].get("cogging_periods_per_rev")
    return bool(true) and abs(step["periods"] - true) <= PERIOD_TOLERANCE * true


def table(rows: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    from transparency_ros.analysis.discrepancy.steps import (  # noqa: PLC0415
        WAVE_CYCLES,
        WAVE_FALSE_ALARM,
    )

    absent = [r for r in rows if _kind(r["truth"]) == "absent"]
    hidden = [r for r in rows if _kind(r["truth"]) == "hidden"]

    waves = (WAVE_CYCLES, float("inf"))  # the rule's periods of travel

    def measure(
        r: dict[str, Any], band: tuple[float, float], of: Any, *, true: bool = False
    ) -> float:
        return max((of(s) for s in _eligible(r, band, true=true)), default=0.0)

    def prominence(s: dict[str, Any]) -> float:
        return float(s["prominence"])

    # waived share: over WAVE_CYCLES periods of travel, the rule's threshold scaled by a ratio
    waived = {
        str(k): {
            "absent_named": sum(measure(r, waves, over_threshold) >= k for r in absent),
            "hidden_named": sum(measure(r, waves, over_threshold, true=True) >= k for r in hidden),
        }
        for k in RATIOS
    }
    # and the flat thresholds of the rule before (15 until issue 26's thirty-third round)
    flat = {
        str(p): {
            "absent_named": sum(measure(r, waves, prominence) >= p for r in absent),
            "hidden_named": sum(measure(r, waves, prominence, true=True) >= p for r in hidden),
        }
        for p in PROMINENCES
    }
    absent_waves = sorted((measure(r, waves, over_threshold) for r in absent), reverse=True)
    hidden_true = sorted(
        (measure(r, waves, over_threshold, true=True) for r in hidden), reverse=True
    )
    lines = [
        "# Cogging's period prominence (drop tests), calibrated on the zoo's campaigns",
        "",
        f"Campaigns: {len(rows)} ({', '.join(sorted({r['campaign'][:-2] + 'xx' for r in rows}))});"
        f" cogging absent (neither required nor allowed) in {len(absent)}, hidden in"
        f" {len(hidden)}. Steps counted: eligible (every condition but the share).",
        "",
        f"The rule (steps.py): a wave over WAVE_CYCLES = {WAVE_CYCLES:g} periods of travel or"
        " more whose prominence reaches prominent_wave(M) = log2(M / WAVE_FALSE_ALARM),"
        f" WAVE_FALSE_ALARM = {WAVE_FALSE_ALARM:g}, M the periods its scan could tell apart,"
        " is named without the share. Below, a step's prominence over its threshold"
        " (1: named; logs made before M was recorded: M from the step's period and travel).",
        "",
        f"Largest prominence over the threshold of an eligible wave over {WAVE_CYCLES:g} periods"
        " of travel or more, per campaign where cogging is absent (top 5): "
        + ", ".join(f"{p:.2f}" for p in absent_waves[:5])
        + "; where it is hidden, of the true period: "
        + ", ".join(f"{p:.2f}" for p in hidden_true),
        "",
        "| prominence over the threshold at least | absent campaigns that would name a wave"
        " (share waived) | hidden campaigns whose true period would be named |",
        "|---|---|---|",
        *(
            f"| {k} | {w['absent_named']}/{len(absent)} | {w['hidden_named']}/{len(hidden)} |"
            for k, w in waived.items()
        ),
        "",
        "The flat thresholds (the rule before issue 26's thirty-third round: 15):",
        "",
        "| prominence at least | absent campaigns that would name a wave |"
        " hidden campaigns whose true period would be named |",
        "|---|---|---|",
        *(
            f"| {p} | {w['absent_named']}/{len(absent)} | {w['hidden_named']}/{len(hidden)} |"
            for p, w in flat.items()
        ),
    ]
    # how few periods of travel a wave may span: per band of periods, the most prominent
    # eligible wave where cogging is absent, and the hidden ones the rule would name there
    bands = []
    for band in CYCLE_BANDS:
        found = [m for r in absent if (m := measure(r, band, over_threshold))]
        largest = sorted(found, reverse=True)
        bands.append({
            "cycles": [band[0], band[1] if band[1] < float("inf") else None],  # (strict JSON)
            "absent_with_a_wave": len(largest),
            "absent_largest": largest[:5],
            "hidden_named": sum(measure(r, band, over_threshold, true=True) >= 1 for r in hidden),
        })  # fmt: skip
    lines += [
        "",
        f"By periods of travel (the rule's WAVE_CYCLES = {WAVE_CYCLES:g}): campaigns where cogging"
        " is absent with an eligible wave in the band, the largest prominences over their"
        " thresholds there, and hidden coggings whose true period reaches its threshold there.",
        "",
        "| periods of travel | absent campaigns with a wave | largest over the threshold"
        " (absent) | hidden at their threshold |",
        "|---|---|---|---|",
        *(
            f"| {band[0]:g}-{band[1]:g} | {b['absent_with_a_wave']}/{len(absent)} |"
            f" {', '.join(f'{p:.2f}' for p in b['absent_largest']) or '-'} |"
            f" {b['hidden_named']}/{len(hidden)} |"
            for band, b in zip(CYCLE_BANDS, bands, strict=True)
        ),
    ]
    spread_lines, spread_data = _spread_table(absent, hidden)
    lines += spread_lines
    data = {
        "spread": spread_data,
        "bands": bands,
        "campaigns": len(rows),
        "absent": len(absent),
        "hidden": len(hidden),
        "thresholds": {
            "false_alarm": WAVE_FALSE_ALARM,
            "cycles": WAVE_CYCLES,
        },
        "absent_largest": absent_waves,
        "hidden_true_largest": hidden_true,
        "waived": waived,
        "flat": flat,
        "median_absent": float(np.median(absent_waves)) if absent_waves else None,
    }
    return lines, data


def _spread_table(
    absent: list[dict[str, Any]], hidden: list[dict[str, Any]]
) -> tuple[list[str], dict[str, Any]]:
    """The second way a wave's share is waived (steps.REPLICATED_SPREAD over
    REPLICATED_CYCLES periods of travel): per threshold, absent campaigns with an eligible
    wave that would be named and hidden ones whose true period would be; per band of periods
    of travel, the absent campaigns' smallest spreads. Logs made before the spread was
    measured (no ``spread``) count as unmeasured."""
    from transparency_ros.analysis.discrepancy.steps import (  # noqa: PLC0415
        REPLICATED_CYCLES,
        REPLICATED_SPREAD,
    )

    def logged(r: dict[str, Any]) -> bool:
        return any("spread" in s for s in r["steps"])

    absent = [r for r in absent if logged(r)]
    hidden = [r for r in hidden if logged(r)]
    measured = absent + hidden

    def least(r: dict[str, Any], band: tuple[float, float], *, true: bool = False) -> float:
        """The smallest spread of the eligible steps over ``band`` periods of travel."""
        return min(
            (s["spread"] for s in _eligible(r, band, true=true) if s.get("spread") is not None),
            default=math.inf,
        )

    rule = (REPLICATED_CYCLES, math.inf)
    named = {
        str(t): {
            "absent_named": sum(least(r, rule) <= t for r in absent),
            "hidden_named": sum(least(r, rule, true=True) <= t for r in hidden),
        }
        for t in SPREADS
    }
    bands = [
        {
            "cycles": [lo, hi if hi < math.inf else None],
            "absent_least": sorted(x for r in absent if (x := least(r, (lo, hi))) < math.inf)[:5],
            "hidden_true": sorted(
                x for r in hidden if (x := least(r, (lo, hi), true=True)) < math.inf
            ),
        }
        for lo, hi in SPREAD_BANDS
    ]
    lines = [
        "",
        f"## Spread over the trials (REPLICATED_SPREAD = {REPLICATED_SPREAD:g},"
        f" REPLICATED_CYCLES = {REPLICATED_CYCLES:g})",
        "",
        f"Campaigns with a cogging step whose spread was logged: {len(measured)} (absent"
        f" {len(absent)}, hidden {len(hidden)}; logs made before it was measured carry none)."
        " A wave every trial shows alike (spread at most the threshold) over"
        f" {REPLICATED_CYCLES:g} periods of travel or more is named without the share.",
        "",
        "| spread at most | absent campaigns that would name a wave | hidden campaigns whose"
        " true period would be named |",
        "|---|---|---|",
        *(
            f"| {t} | {w['absent_named']}/{len(absent)} | {w['hidden_named']}/{len(hidden)} |"
            for t, w in named.items()
        ),
        "",
        "Smallest spreads of eligible waves per band of periods of travel: where cogging is"
        " absent (per campaign, the 5 smallest) and of hidden coggings' true periods.",
        "",
        "| periods of travel | absent (smallest) | hidden, true period |",
        "|---|---|---|",
        *(
            f"| {b['cycles'][0]:g}-{b['cycles'][1] if b['cycles'][1] is not None else 'inf'} |"
            f" {', '.join(f'{x:.2f}' for x in b['absent_least']) or '-'} |"
            f" {', '.join(f'{x:.2f}' for x in b['hidden_true']) or '-'} |"
            for b in bands
        ),
    ]
    return lines, {"named": named, "bands": bands, "measured": len(measured)}


def main(argv: list[str] | None = None) -> int:
    from share_calibration import calibration_main  # noqa: PLC0415

    return calibration_main(
        argv,
        __doc__,
        name="prominence_calibration",
        logged="every cogging step",
        analyse=log_campaign,
        table=table,
        keys={"campaign", "found", "steps", "truth"},
    )


if __name__ == "__main__":
    raise SystemExit(main())
