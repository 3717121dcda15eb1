"""The drop-test rule's tolerance for "explained alike", calibrated on the zoo.

    .venv/bin/python benchmarks/alike_calibration.py log --zoo DIR --seeds 10800-10899 \
        --log LOG.jsonl [--jobs N]
    .venv/bin/python benchmarks/alike_calibration.py table LOG.jsonl[.gz]... [--out DIR]

results/alike_calibration.md comes from ``table benchmarks/results/alike_calibration/*.jsonl.gz``
(the logs of seeds 10800-10999, compressed).

Each round of the search names the best of the candidates that pass the naming rule
(``steps.choose``): steps whose held-out RMSE is within ``ALIKE`` (5 %) of the best by the
information criterion, or that both reach the floor they are judged on, are taken as
explaining the recordings alike, and the one with the fewest parameters is named (then one
the recording predicts, then one that does not yield to the others). A cogging whose wave
explains 4 % less of the error than an offset is named as the offset; is 5 % the right
tolerance, or is it where misses come from?

``log`` runs the tool on drop_zoo campaigns (made beforehand with ``drop_zoo.py DIR --seeds``)
and writes every choice of a round (the steps that passed the rule, and which was named) with
the campaign's truth: JSON lines, one per campaign, appended.

``table`` reads such logs and takes every logged choice again with other tolerances, by
``steps.choose`` itself (``pick``; with ``ALIKE`` it must give the logged choice, and the table
says in how many choices it does). First-order, per campaign its first choice that changes (a name
taken otherwise changes the rounds after it): whether the effect named instead is required,
allowed or neither by the truth, against the one named.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))

TOLERANCES = [1.00, 1.02, 1.03, 1.04, 1.05, 1.07, 1.10, 1.15, 1.20]
KEYS = {"campaign", "found", "choices", "truth"}


def log_choices(campaign: Path) -> dict[str, Any]:
    """The tool on one campaign, every choice of a round recorded."""
    from transparency_ros.analysis.discrepancy import discover as d  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.drop import (  # noqa: PLC0415
        DropProblem,
        load_drop_nominal,
        load_drop_trial,
    )
    from transparency_ros.analysis.discrepancy.fitting import parameter_count  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.steps import choose  # noqa: PLC0415
    from transparency_ros.bag.reader import find_bags  # noqa: PLC0415

    choices: list[list[dict[str, Any]]] = []

    class Logged(d.Discoverer):
        def _choose(self, steps):  # type: ignore[no-untyped-def]
            expected = getattr(self.problem, "expected", lambda _e, _p: False)
            best = choose(steps, expected)
            if steps:
                choices.append([
                    {
                        "names": [a.name for a in s.added],
                        "rmse": float(s.rmse),
                        "judged": [float(x) for x in s.judged],
                        "aic": float(s.aic),
                        "k": sum(parameter_count(a, p) for a, p in s.new()),
                        "expected": all(expected(a, p) for a, p in s.new()),
                        "yields": max(getattr(a, "yields_to", 0) for a in s.added),
                        "chosen": s is best,
                    }
                    for s in steps
                ])  # fmt: skip
            return best

    try:
        trials = [load_drop_trial(b) for b in find_bags([str(campaign)])]
        problem = DropProblem(trials, load_drop_nominal(None, trials))
        found: Any = [f.effect for f in Logged(problem).run().findings]
    except Exception as err:  # noqa: BLE001 - a failure is a result here, with its reason
        found = f"error: {type(err).__name__}: {err}"
    return {"campaign": campaign.name, "found": found, "choices": choices}


def as_step(entry: dict[str, Any]) -> Any:
    """A logged step as ``steps.choose`` sees it (its effects: name, parameter count, whether
    it yields to others)."""
    import numpy as np  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy.steps import Step  # noqa: PLC0415

    effects = [
        SimpleNamespace(name=n, discrete_choices=0, yields_to=entry["yields"])
        for n in entry["names"]
    ]
    # (the step's parameters all on its first effect: choose() counts only their sum)
    params = [np.zeros(entry["k"] if i == 0 else 0) for i in range(len(effects))]
    return Step(
        added=effects, params=params, err=np.zeros(1), rmse=entry["rmse"], aic=entry["aic"],
        gain=0.0, judged=tuple(entry["judged"]), result=None, meaningful=True,
    )  # fmt: skip


def pick(steps: list[dict[str, Any]], tolerance: float) -> dict[str, Any]:
    """The logged step ``steps.choose`` names among ``steps`` with ``tolerance`` for ALIKE."""
    from transparency_ros.analysis.discrepancy.steps import choose  # noqa: PLC0415

    made = [as_step(s) for s in steps]
    # (a step's flag on each of its effects: choose() asks all of them)
    expected = {id(a): s["expected"] for m, s in zip(made, steps, strict=True) for a in m.added}
    named = choose(made, lambda a, _p: expected[id(a)], tolerance=tolerance)
    return next(s for m, s in zip(made, steps, strict=True) if m is named)


def kind(names: list[str], truth: dict[str, Any]) -> str:
    """'required' (every effect of the step is), 'allowed' (each is one or the other) or
    'false' (one is neither) by the campaign's truth."""
    if all(n in truth["required"] for n in names):
        return "required"
    if all(n in truth["required"] or n in truth["allowed"] for n in names):
        return "allowed"
    return "false"


def table(rows: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    from transparency_ros.analysis.discrepancy.steps import ALIKE  # noqa: PLC0415

    choices = [c for r in rows for c in r["choices"]]
    same = sum(pick(c, ALIKE) is next(s for s in c if s["chosen"]) for c in choices)
    contested = sum(len(c) > 1 for c in choices)
    per: dict[str, Any] = {}
    for tol in TOLERANCES:
        moves: dict[str, int] = {}
        campaigns = []
        for r in rows:
            for c in r["choices"]:
                old, new = next(s for s in c if s["chosen"]), pick(c, tol)
                if new is old:
                    continue
                move = f"{kind(old['names'], r['truth'])} -> {kind(new['names'], r['truth'])}"
                moves[move] = moves.get(move, 0) + 1
                campaigns.append(
                    f"{r['campaign']}: {'+'.join(old['names'])} -> {'+'.join(new['names'])}"
                )
                break  # (first-order: the first choice that changes)
        was_false = {m: m.startswith("false ->") for m in moves}
        is_false = {m: m.endswith("-> false") for m in moves}
        per[f"{tol:.2f}"] = {
            "campaigns_changed": len(campaigns),
            "false_mended": sum(n for m, n in moves.items() if was_false[m] and not is_false[m]),
            "false_made": sum(n for m, n in moves.items() if is_false[m] and not was_false[m]),
            "moves": moves,
            "changes": campaigns,
        }
    lines = [
        "# The tolerance for 'explained alike' (drop tests), calibrated on the zoo's campaigns",
        "",
        f"Campaigns: {len(rows)} ({', '.join(sorted({r['campaign'][:-2] + 'xx' for r in rows}))});"
        f" {len(choices)} choices of a round, {contested} between two steps or more."
        f" Taken again with the package's tolerance ({ALIKE:.2f}), {same} of {len(choices)}"
        " give the logged choice. First-order: per campaign its first choice that changes;"
        " what is named instead against what was (required / allowed / false by the truth).",
        "",
        "| tolerance | campaigns changed | false finding mended | false finding made | changes |",
        "|---|---|---|---|---|",
    ]
    for tol, p in per.items():
        moves = ", ".join(f"{m}: {n}" for m, n in sorted(p["moves"].items())) or "-"
        lines.append(
            f"| {tol} | {p['campaigns_changed']} | {p['false_mended']} | {p['false_made']} |"
            f" {moves} |"
        )
    data = {
        "alike": ALIKE,
        "campaigns": len(rows),
        "choices": len(choices),
        "contested": contested,
        "reproduced": same,
        "tolerances": per,
    }
    return lines, data


def main(argv: list[str] | None = None) -> int:
    from share_calibration import calibration_main  # noqa: PLC0415

    return calibration_main(
        argv,
        __doc__,
        name="alike_calibration",
        logged="every choice",
        analyse=log_choices,
        table=table,
        keys=KEYS,
    )


if __name__ == "__main__":
    raise SystemExit(main())
