"""A replication test for any single drop-test effect, measured on the zoo (tried, not kept).

    .venv/bin/python benchmarks/replication_calibration.py log --zoo DIR --seeds 13200-13272 \
        --log LOG.jsonl [--jobs N]
    .venv/bin/python benchmarks/replication_calibration.py table LOG.jsonl[.gz]... [--out DIR]

results/replication_calibration.md comes from ``table
benchmarks/results/replication_calibration/*.jsonl.gz``.

An effect is named where it removes 0.75 of the held-out error above the noise floor
(``Discoverer._names``). A cogging wave that every trial, fitted on its own, shows alike is
named without that share (``steps.REPLICATED_SPREAD``): the motor's wave is the same in every
trial, a wave standing in for something else is not. Would the same test carry to any single
effect? On zoo_13703 (an offset of -0.094 N m beside a 512-count lattice) the offset removes
68.4 % and is refused, while each trial fitted on its own wants the same offset.

The *replication spread* of an effect added to the model (``spread_of``): each trial (fitting
and held-out) refits the effect's parameters on its own, linearised about the joint fit (a
Jacobian by finite differences, one simulation per parameter, and one at the effect's null
value, or without the effect where it has none, for its contribution); the change of the
trial's model that refit makes, over the effect's contribution in that trial (at most
``CAP``), weighted by the contribution's square. 0: every trial wants the fitted values.

``log`` runs the tool on drop_zoo campaigns (made beforehand with ``drop_zoo.py DIR --seeds``)
unchanged and records, with the campaign's truth, every single step that the loop's own rule
(``Discoverer._names``) would name with no share asked (meaningful, interval off its null, a
tenth of the floor, the criterion by 10) and that removes at least ``LOGGED_SHARE``, with its
spread.

``table`` reads such logs. First-order (the logged rounds, not a re-run):
- *as a waiver*: per campaign and effect not named, its least spread among its steps in the
  band (removing less than the share it needed); how many such effects the truth requires,
  allows or neither, with a spread at most T, for each T of ``THRESHOLDS``;
- *as a refusal*: per effect named, its first naming step's spread; how many of those above
  T the truth requires, allows or neither.
Measured on development seeds 13200-13349 and fresh seeds 13800-13899 it separates neither
way (docs/discrepancy.md, thirty-sixth and thirty-seventh sessions): smooth stand-ins
(drifts, offsets, delays) fit each trial alike, as the model's own error in the contact and
friction laws is every trial's.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

CAP = 3.0  # a trial's refit counted at most 3 times the effect's contribution
LOGGED_SHARE = 0.2  # steps removing less are not logged
THRESHOLDS = [0.02, 0.05, 0.1, 0.15, 0.2, 0.3]
KEYS = {"campaign", "found", "declared", "steps", "truth"}
KINDS = ("required", "allowed", "neither")


def spread_of(problem: Any, effects: list[Any], params: list[Any], effect: Any) -> float:
    """The replication spread (module docstring) of ``effect``, added to ``effects`` with all
    parameters ``params`` (its own last). NaN where nothing of it is fitted or the problem
    does not say which trial each element of its error is of."""
    index = getattr(problem, "trial_index", None)
    if index is None or not getattr(effect, "fittable", True):
        return math.nan
    x = np.asarray(params[-1], dtype=float)
    before = list(params[:-1])
    lower, upper = np.asarray(effect.lower, float), np.asarray(effect.upper, float)
    sets = [list(params)]
    null = getattr(effect, "null", None)
    if null is not None:  # (a NaN null: any value, the fitted one kept)
        at_null = [v if math.isnan(n) else n for v, n in zip(x, null, strict=True)]
        sets.append([*before, np.array(at_null)])
    steps = []
    for j in range(x.size):
        span = upper[j] - lower[j] if np.isfinite(upper[j] - lower[j]) else max(abs(x[j]), 1.0)
        h = max(1e-3 * abs(x[j]), 1e-4 * span, 1e-9)
        h = -h if x[j] + h > upper[j] else h
        moved = x.copy()
        moved[j] += h
        steps.append(h)
        sets.append([*before, moved])
    weights: list[float] = []
    shares: list[float] = []
    for held in (False, True):
        errors = problem.error_sets([*effects, effect], sets, held)
        fitted, columns = errors[0], errors[1 + (null is not None) :]
        without = errors[1] if null is not None else problem.error_sets(effects, [before], held)[0]
        jacobian = np.stack([(c - fitted) / h for c, h in zip(columns, steps, strict=True)], axis=1)
        contribution = without - fitted
        trial = index(held)
        for i in np.unique(trial):
            m = trial == i
            size = float(np.linalg.norm(contribution[m]))
            if size <= 0:
                continue
            own = np.linalg.lstsq(jacobian[m], -fitted[m], rcond=None)[0]
            shares.append(min(float(np.linalg.norm(jacobian[m] @ own)) / size, CAP))
            weights.append(size**2)
    total = sum(weights)
    return float(np.dot(weights, shares) / total) if total > 0 else math.nan


def log_campaign(campaign: Path) -> dict[str, Any]:
    """The tool on one campaign, unchanged; the steps of the band and those that name, with
    their spread."""
    from share_calibration import logged_run  # noqa: PLC0415

    def record(loop: Any, s: Any, base: Any, _cand: Any, _kw: Any) -> dict[str, Any] | None:
        # the loop's own rule with no share asked (Discoverer._names): what the share decides
        if not (len(s.added) == 1 and s.gain >= LOGGED_SHARE and loop._names(s, base, 0.0)):
            return None
        effect = s.added[0]  # (a drift reduced to the terms that drifted: that one)
        spread = spread_of(loop.problem, base.effects, s.params, effect)
        return {
            "stage": type(loop.problem).__name__,
            "before": [e.name for e in base.effects],
            "cand": effect.name,
            "gain": float(s.gain),
            "needed": float(loop._share(s)),
            "names": bool(loop._names(s, base)),
            "params": [float(v) for v in s.params[-1]],
            "spread": None if math.isnan(spread) else spread,  # (strict JSON)
        }

    found, declared, steps = logged_run(campaign, record)
    return {"campaign": campaign.name, "found": found, "declared": declared, "steps": steps}


def kind(cand: str, truth: dict[str, Any]) -> str:
    if cand in truth["required"]:
        return "required"
    return "allowed" if cand in truth.get("allowed", []) else "neither"


def table(rows: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    band: list[tuple[str, float]] = []  # (kind, least spread) per campaign and effect not named
    first: list[tuple[str, float]] = []  # (kind, spread) of each effect's first naming step
    for r in rows:
        unnamed: dict[str, float] = {}
        named: dict[str, float] = {}
        for s in r["steps"]:
            spread = s["spread"]
            if spread is None or math.isnan(spread):
                continue
            if s["names"]:
                if s["cand"] in r["found"]:
                    named.setdefault(s["cand"], spread)
            elif s["gain"] < s["needed"] and s["cand"] not in r["found"]:
                unnamed[s["cand"]] = min(unnamed.get(s["cand"], math.inf), spread)
        band += [(kind(c, r["truth"]), v) for c, v in unnamed.items()]
        first += [(kind(c, r["truth"]), v) for c, v in named.items()]

    def counts(pairs: list[tuple[str, float]], keep: Any) -> dict[str, int]:
        n = Counter(k for k, v in pairs if keep(v))
        return {k: n[k] for k in KINDS}

    waiver = {str(t): counts(band, lambda v, t=t: v <= t) for t in THRESHOLDS}
    refusal = {str(t): counts(first, lambda v, t=t: v > t) for t in THRESHOLDS}
    in_band, all_named = counts(band, lambda _v: True), counts(first, lambda _v: True)
    sets = sorted({r["campaign"][:-2] + "xx" for r in rows})  # (the seeds' hundreds)
    lines = [
        "# A replication test for any single effect (drop tests), measured on the zoo",
        "",
        f"Campaigns: {len(rows)} ({', '.join(sets)}), the tool unchanged. First-order:"
        " the logged rounds. Kinds by the campaign's truth: required / allowed / neither.",
        "",
        "*As a waiver of the share*: effects not named whose steps removed "
        f"{LOGGED_SHARE}-0.75 of the error, with a spread at most T "
        f"(in the band: {in_band['required']} / {in_band['allowed']} / {in_band['neither']}).",
        "",
        "| T | required | allowed | neither |",
        "|---|---|---|---|",
        *_rows(waiver),
        "",
        "*As a refusal*: effects named whose first naming step's spread is above T (named: "
        f"{all_named['required']} / {all_named['allowed']} / {all_named['neither']}).",
        "",
        "| T | required | allowed | neither |",
        "|---|---|---|---|",
        *_rows(refusal),
    ]
    data = {
        "campaigns": len(rows),
        "in_band": in_band,
        "named": all_named,
        "waiver": waiver,
        "refusal": refusal,
    }
    return lines, data


def _rows(by_threshold: dict[str, dict[str, int]]) -> list[str]:
    return [
        f"| {t} | {c['required']} | {c['allowed']} | {c['neither']} |"
        for t, c in by_threshold.items()
    ]


def main(argv: list[str] | None = None) -> int:
    from share_calibration import calibration_main  # noqa: PLC0415

    return calibration_main(
        argv,
        __doc__,
        name="replication_calibration",
        logged="the steps near the share, with their spread",
        analyse=log_campaign,
        table=table,
        keys=KEYS,
    )


if __name__ == "__main__":
    raise SystemExit(main())
