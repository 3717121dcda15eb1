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

PROMINENCES = [2.0, 3.0, 5.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0]
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


def _true_period(step: dict[str, Any], truth: dict[str, Any]) -> bool:
    true = truth["params"].get("cogging_periods_per_rev")
    return bool(true) and abs(step["periods"] - true) <= PERIOD_TOLERANCE * true


def table(rows: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    from transparency_ros.analysis.discrepancy.discover import (  # noqa: PLC0415
        PROMINENT_WAVE,
        WAVE_CYCLES,
    )

    absent = [r for r in rows if _kind(r["truth"]) == "absent"]
    hidden = [r for r in rows if _kind(r["truth"]) == "hidden"]

    waves = (WAVE_CYCLES, float("inf"))  # the rule's periods of travel

    def prominences(
        r: dict[str, Any], band: tuple[float, float], *, true: bool = False
    ) -> list[float]:
        return [s["prominence"] for s in _eligible(r, band, true=true)]

    def most(r: dict[str, Any], band: tuple[float, float], *, true: bool = False) -> float:
        return max(prominences(r, band, true=true), default=0.0)

    # waived share: over WAVE_CYCLES periods of travel, at or above a prominence
    waived = {
        str(p): {
            "absent_named": sum(most(r, waves) >= p for r in absent),
            "hidden_named": sum(most(r, waves, true=True) >= p for r in hidden),
        }
        for p in PROMINENCES
    }
    absent_waves = sorted((most(r, waves) for r in absent), reverse=True)
    hidden_true = sorted((most(r, waves, true=True) for r in hidden), reverse=True)
    lines = [
        "# Cogging's period prominence (drop tests), calibrated on the zoo's campaigns",
        "",
        f"Campaigns: {len(rows)} ({', '.join(sorted({r['campaign'][:-2] + 'xx' for r in rows}))});"
        f" cogging absent (neither required nor allowed) in {len(absent)}, hidden in"
        f" {len(hidden)}. Steps counted: eligible (every condition but the share).",
        "",
        f"The rule ships PROMINENT_WAVE = {PROMINENT_WAVE:g}, WAVE_CYCLES = {WAVE_CYCLES:g}"
        " (steps.py): a wave at least this prominent over at least this many periods of"
        " travel is named without the share.",
        "",
        f"Largest prominence of an eligible wave over {WAVE_CYCLES:g} periods of travel or more,"
        " per campaign where cogging is absent (top 5): "
        + ", ".join(f"{p:.1f}" for p in absent_waves[:5])
        + "; where it is hidden, of the true period: "
        + ", ".join(f"{p:.1f}" for p in hidden_true),
        "",
        "| prominence at least | absent campaigns that would name a wave (share waived) |"
        " hidden campaigns whose true period would be named |",
        "|---|---|---|",
        *(
            f"| {p} | {w['absent_named']}/{len(absent)} | {w['hidden_named']}/{len(hidden)} |"
            for p, w in waived.items()
        ),
    ]
    # how few periods of travel a wave may span: per band of periods, the most prominent
    # eligible wave where cogging is absent, and the hidden ones the rule would name there
    bands = []
    for band in CYCLE_BANDS:
        found = [p for p in (prominences(r, band) for r in absent) if p]
        largest = sorted((max(p) for p in found), reverse=True)
        bands.append({
            "cycles": [band[0], band[1] if band[1] < float("inf") else None],  # (strict JSON)
            "absent_with_a_wave": len(largest),
            "absent_largest": largest[:5],
            "hidden_named": sum(most(r, band, true=True) >= PROMINENT_WAVE for r in hidden),
        })  # fmt: skip
    lines += [
        "",
        f"By periods of travel (the rule's WAVE_CYCLES = {WAVE_CYCLES:g}): campaigns where cogging"
        " is absent with an eligible wave in the band, the largest prominences there, and hidden"
        f" coggings whose true period reaches {PROMINENT_WAVE:g} there.",
        "",
        "| periods of travel | absent campaigns with a wave | largest prominence (absent) |"
        f" hidden named at {PROMINENT_WAVE:g} |",
        "|---|---|---|---|",
        *(
            f"| {band[0]:g}-{band[1]:g} | {b['absent_with_a_wave']}/{len(absent)} |"
            f" {', '.join(f'{p:.1f}' for p in b['absent_largest']) or '-'} |"
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
            "prominent": PROMINENT_WAVE,
            "cycles": WAVE_CYCLES,
        },
        "absent_largest": absent_waves,
        "hidden_true_largest": hidden_true,
        "waived": waived,
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
