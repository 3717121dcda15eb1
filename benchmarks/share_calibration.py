"""Per-candidate shares for the discrepancy tool's drop-test rule, calibrated on the zoo.

    .venv/bin/python benchmarks/share_calibration.py log --zoo DIR --seeds 10300-10399 \
        --log LOG.jsonl [--jobs N]
    .venv/bin/python benchmarks/share_calibration.py table LOG.jsonl[.gz]... [--out DIR]

results/share_calibration.md comes from ``table benchmarks/results/share_calibration/*.jsonl.gz``
(the logs of seeds 10300-10499, compressed).

A drop-test effect is named where it removes a share of the held-out error above the noise
floor (``Discoverer._names``): 0.75 for every effect. Could a share per candidate do better?
A cogging the fit finds (size and period within 10 % of the truth) removes 0.5-0.7 of the
error beside the model's own error in the contact and friction laws, which the noise floor
does not count, while a drift or a spring standing in for something else may remove as much.

``log`` runs the tool on drop_zoo campaigns (``../shared/plants/drop_zoo.py``, made beforehand
with it: ``drop_zoo.py DIR --seeds ...``) under the one share, and writes every candidate's
single step (each round, each stage: kinematics, load cell) with the campaign's truth: JSON
lines, one per campaign, appended (a campaign already in the log is skipped).

``table`` reads such logs. Per candidate, the *decisive share* in a campaign is the largest
share it removed in a round where it would have been named had its own share been lower: its
fit meaningful, its interval off its null, a tenth of the floor removed, the held-out
information criterion better by 10, and no step named in that round better by the criterion.
Two ways to set a candidate's share from them:
- the *1 % rule*: the least of 0.50, 0.55, ..., 0.95 at which at most ``RATE`` of the
  campaigns where the effect is absent (neither required nor allowed by the truth) would have
  named it; one that names it falsely even at 0.95 does not count (it stood in for all of the
  error there, which no share refuses); absent from fewer than ``MIN_ABSENT`` campaigns (the
  encoder's lattice, allowed wherever an encoder is coarse): the uniform share;
- *balanced*: the share that mends the most campaigns less those it loses (``changed``: a
  hidden effect named or lost, a false finding made or mended).
Both are first-order: the logged rounds of the uniform rule, not a re-run (a name taken
earlier changes the rounds after it). The zoo survey on fresh seeds is the measure: the
1 % rule's shares, shipped for one round, took fresh seeds 10600-10699 from 78 to 76
campaigns fully right (docs/discrepancy.md, seventeenth round), and the package keeps one
share.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from collections import defaultdict
from collections.abc import Callable
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).parent))

RATE = 0.01  # campaigns (where the effect is absent) that may name it
MIN_ABSENT = 50  # a candidate absent from fewer campaigns keeps the uniform share
SHARES = [round(0.5 + 0.05 * k, 2) for k in range(10)]  # 0.50 ... 0.95
UNIFORM = 0.75  # the one share the logs are made under


def log_campaign(campaign: Path) -> dict[str, Any]:
    """The tool on one campaign under the uniform share, every single step recorded."""
    from transparency_ros.analysis.discrepancy.steps import null_inside  # noqa: PLC0415

    def record(loop: Any, s: Any, base: Any, cand: Any, kw: Any) -> Any:
        return {
            "stage": type(loop.problem).__name__,
            "before": [e.name for e in base.effects],
            "cand": cand.name,
            "gain": float(s.gain),
            "judged": [float(x) for x in s.judged],
            "daic": float(s.aic - base.aic),
            "meaningful": bool(s.meaningful),
            "null_in": bool(null_inside(s)),
            "names": bool(loop._names(s, base)),
            "params": [float(v) for v in s.params[-1]],
            "after_search": bool(kw.get("after_search", False)),
        }  # fmt: skip

    found, declared, steps = logged_run(campaign, record, min_improvement=UNIFORM)
    return {"campaign": campaign.name, "found": found, "declared": declared, "steps": steps}


def logged_run(
    campaign: Path, record: Callable[..., dict[str, Any] | None], **loop: Any
) -> tuple[Any, list[str], list[dict[str, Any]]]:
    """The tool on one drop-test campaign (``loop``: the Discoverer's keyword arguments),
    ``record`` called on every single step as (loop, step, the round's base — its effects are
    those before the step —, the candidate, the step's keyword arguments): what it returns is
    logged (None: nothing). Returns (the effects found, or the error as "error: ..."; the declared
    candidates; the records). Also benchmarks/prominence_calibration.py's."""
    from transparency_ros.analysis.discrepancy import discover as d  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.drop import (  # noqa: PLC0415
        DropProblem,
        load_drop_nominal,
        load_drop_trial,
    )
    from transparency_ros.bag.reader import find_bags  # noqa: PLC0415

    records: list[dict[str, Any]] = []

    class Logged(d.Discoverer):
        def _single(self, effects, params, cand, base, **kw):  # type: ignore[no-untyped-def]
            s = super()._single(effects, params, cand, base, **kw)
            row = record(self, s, base, cand, kw)
            if row is not None:
                records.append(row)
            return s

    try:
        trials = [load_drop_trial(b) for b in find_bags([str(campaign)])]
        problem = DropProblem(trials, load_drop_nominal(None, trials))
        declared = [c.name for c in problem.candidates() if getattr(c, "declared", False)]
        report = Logged(problem, **loop).run()
        found: Any = [f.effect for f in report.findings]
    except Exception as err:  # noqa: BLE001 - a failure is a result here, with its reason
        found, declared = f"error: {type(err).__name__}: {err}", []
    return found, declared, records


def decisive(row: dict[str, Any]) -> dict[str, float]:
    """Per candidate (not declared: those are named by another rule), its decisive share in
    this campaign (module docstring); candidates that never had such a round are left out."""
    rounds: dict[tuple[Any, ...], list[dict[str, Any]]] = defaultdict(list)
    for s in row["steps"]:
        rounds[(s["stage"], tuple(s["before"]), s["after_search"])].append(s)
    best: dict[str, float] = {}
    for steps in rounds.values():
        named = [s for s in steps if s["names"]]
        top = min((s["daic"] for s in named), default=0.0)
        for s in steps:
            before, after, floor = s["judged"]
            if (
                s["cand"] not in row["declared"]
                and s["meaningful"]
                and not s["null_in"]
                and before - after >= 0.1 * floor
                and s["daic"] < -10
                and s["daic"] <= top
            ):
                best[s["cand"]] = max(best.get(s["cand"], -np.inf), s["gain"])
    return best


def _verdicts(
    rows: list[dict[str, Any]], cand: str, decided: list[dict[str, float]] | None = None
) -> list[tuple[str, float, bool]]:
    """Per campaign where ``cand`` is hidden ("hidden") or absent ("absent": neither required
    nor allowed): its decisive share (-inf: none) and whether the uniform rule named it.
    ``decided``: each row's :func:`decisive` shares, worked out once for every candidate."""
    if decided is None:
        decided = [decisive(r) for r in rows]
    out = []
    for r, shares in zip(rows, decided, strict=True):
        truth = r["truth"]
        kind = (
            "hidden"
            if cand in truth["required"]
            else ("absent" if cand not in truth["allowed"] else "")
        )
        if kind:
            out.append((kind, shares.get(cand, -np.inf), cand in r["found"]))
    return out


def changed(verdicts: list[tuple[str, float, bool]], share: float) -> tuple[int, int]:
    """(campaigns mended, campaigns lost) with ``share`` for this candidate in place of the
    uniform one, first-order: below it, a hidden effect not named whose decisive share
    reaches it is mended, an absent one not named falsely until then is a new false finding;
    above it, a false finding whose decisive share is under it is mended, a hidden effect
    named with a decisive share under it is lost."""
    lo, hi = min(share, UNIFORM), max(share, UNIFORM)
    between = [(k, f) for k, d, f in verdicts if lo <= d < hi]
    if share < UNIFORM:
        return (
            sum(k == "hidden" and not f for k, f in between),
            sum(k == "absent" and not f for k, f in between),
        )
    return (
        sum(k == "absent" and f for k, f in between),
        sum(k == "hidden" and f for k, f in between),
    )


def table(rows: list[dict[str, Any]]) -> tuple[list[str], dict[str, Any]]:
    candidates = sorted({s["cand"] for r in rows for s in r["steps"]} - {
        c for r in rows for c in r["declared"]
    })  # fmt: skip
    per: dict[str, Any] = {}
    decided = [decisive(r) for r in rows]
    for cand in candidates:
        verdicts = _verdicts(rows, cand, decided)
        absent = np.array([d for k, d, _ in verdicts if k == "absent"])
        named_absent = {t: int(np.sum(absent >= t)) for t in SHARES}
        # the false-naming rule: (where it is named falsely at the highest share too, it
        # stands in for the whole error there: no share refuses that)
        allowed = named_absent[SHARES[-1]] + int(RATE * absent.size)
        rate_share = (
            next(t for t in SHARES if named_absent[t] <= allowed)
            if absent.size >= MIN_ABSENT
            else UNIFORM
        )
        change = {t: changed(verdicts, t) for t in SHARES}
        # the balanced rule: most campaigns mended less lost; on a tie the uniform share,
        # else the nearest to it
        best = max(
            SHARES,
            key=lambda t: (change[t][0] - change[t][1], t == UNIFORM, -abs(t - UNIFORM)),
        )
        per[cand] = {
            "rate_share": rate_share,
            "rate_share_change": list(change[rate_share]),
            "best_share": best,
            "best_share_change": list(change[best]),
            "absent_campaigns": int(absent.size),
            "hidden_campaigns": sum(k == "hidden" for k, _, _ in verdicts),
            "named_where_absent": {str(t): n for t, n in named_absent.items()},
            "change": {str(t): list(c) for t, c in change.items()},
        }
    lines = [
        "# Per-candidate shares (drop tests), calibrated on the zoo's campaigns",
        "",
        f"Campaigns: {len(rows)} ({', '.join(sorted({r['campaign'][:-2] + 'xx' for r in rows}))}),"
        f" logged under one share ({UNIFORM}) for every effect. Changes are first-order (the"
        " logged rounds), in campaigns: mended / lost against the uniform share.",
        f"*1 % rule*: the least share of {SHARES[0]}-{SHARES[-1]} at which at most {RATE:.0%}"
        f" of the campaigns where the effect is absent would have named it (those that name it"
        f" at {SHARES[-1]} too not counted; absent from fewer than {MIN_ABSENT}: {UNIFORM}).",
        "*Balanced*: the share mending the most campaigns less those it loses (a tie: the"
        " uniform share, else the nearest to it).",
        "",
        "| candidate | absent in | hidden in | 1 % rule | its change | balanced | its change |",
        "|---|---|---|---|---|---|---|",
    ]
    for cand, p in per.items():
        rate, best = p["rate_share_change"], p["best_share_change"]
        lines.append(
            f"| {cand} | {p['absent_campaigns']} | {p['hidden_campaigns']} | "
            f"{p['rate_share']:.2f} | +{rate[0]} / -{rate[1]} | "
            f"{p['best_share']:.2f} | +{best[0]} / -{best[1]} |"
        )
    return lines, {"rate": RATE, "uniform": UNIFORM, "campaigns": len(rows), "candidates": per}


def main(argv: list[str] | None = None) -> int:
    return calibration_main(
        argv,
        __doc__,
        name="share_calibration",
        logged="every single step",
        analyse=log_campaign,
        table=table,
        keys={"campaign", "found", "declared", "steps", "truth"},
    )


def calibration_main(
    argv: list[str] | None,
    doc: str,
    *,
    name: str,
    logged: str,
    analyse: Callable[[Path], dict[str, Any]],
    table: Callable[[list[dict[str, Any]]], tuple[list[str], dict[str, Any]]],
    keys: set[str],
) -> int:
    """A calibration benchmark's command line: ``log`` (``analyse`` on zoo campaigns, what it
    records appended to a log) and ``table`` (``table`` of logs whose rows have ``keys``,
    written to results/``name``.md and .json); also benchmarks/alike_calibration.py's."""
    from _results import write_results  # noqa: PLC0415

    parser = argparse.ArgumentParser(description=doc.split("\n\n", maxsplit=1)[0])
    sub = parser.add_subparsers(dest="command", required=True)
    log = sub.add_parser("log", help=f"run the tool on campaigns, {logged} logged")
    log.add_argument("--zoo", type=Path, required=True, help="campaigns made by drop_zoo.py")
    log.add_argument("--seeds", required=True, help="A-B")
    log.add_argument("--log", type=Path, required=True, help="JSON lines, appended")
    log.add_argument("--jobs", type=int, default=1, help="campaigns analysed at once")
    tab = sub.add_parser("table", help="the table from logs")
    tab.add_argument("logs", type=Path, nargs="+")
    tab.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    if args.command == "log":
        return _log(parser, args, analyse)
    rows, failed = read_logs(parser, args.logs, keys)
    lines, data = table(rows)
    if failed:  # (said, not dropped silently)
        lines[2:2] = [f"Left out, the tool failed on them: {', '.join(failed)}.", ""]
        data["failed"] = failed
    write_results(args.out, name, lines, data)
    return 0


def read_logs(
    parser: argparse.ArgumentParser, paths: list[Path], keys: set[str]
) -> tuple[list[dict[str, Any]], list[str]]:
    """The rows of logs (each with ``keys``) of campaigns the tool ran on, and the names of
    those it failed on; a file that is no such log is refused by ``parser``."""
    rows = []
    for path in paths:
        try:
            rows += [json.loads(line) for line in _read(path).splitlines()]
        except (OSError, ValueError) as err:  # (json and gzip errors are ValueErrors)
            parser.error(f"{path}: not a log of this script ({err})")
        if any(not isinstance(r, dict) or not keys <= r.keys() for r in rows):
            parser.error(f"{path}: not a log of this script (a line without {sorted(keys)})")
    failed = [r["campaign"] for r in rows if not isinstance(r["found"], list)]
    rows = [r for r in rows if isinstance(r["found"], list)]
    if not rows:
        parser.error("no campaign analysed without error in the logs")
    return rows, failed


def _read(path: Path) -> str:
    """A log's text (``.gz``: compressed, as the committed logs are)."""
    return gzip.decompress(path.read_bytes()).decode() if path.suffix == ".gz" else path.read_text()


def _log(
    parser: argparse.ArgumentParser,
    args: argparse.Namespace,
    analyse: Callable[[Path], dict[str, Any]] = log_campaign,
) -> int:
    """``log``: ``analyse`` (one campaign -> its row) on the seeds not yet in the log, each
    row appended with the campaign's truth (also benchmarks/alike_calibration.py's)."""
    answers_file = args.zoo / "answers.yaml"
    if not answers_file.is_file():
        parser.error(f"--zoo {args.zoo}: no answers.yaml (make it with drop_zoo.py)")
    answers = yaml.safe_load(answers_file.read_text())
    first, _, last = args.seeds.partition("-")
    if not (first.isdigit() and (last or first).isdigit()):
        parser.error(f"--seeds {args.seeds!r}: expected A-B or A (numbers)")
    seeds = range(int(first), int(last or first) + 1)
    done = set()
    if args.log.is_file():
        done = {json.loads(line)["campaign"] for line in args.log.read_text().splitlines()}
    todo = [args.zoo / f"zoo_{s}" for s in seeds if f"zoo_{s}" not in done]
    missing = [c.name for c in todo if c.name not in answers]
    if missing:
        parser.error(f"--zoo {args.zoo}: no campaign {missing[0]} in answers.yaml")
    args.log.parent.mkdir(parents=True, exist_ok=True)
    with Pool(args.jobs) as pool, args.log.open("a") as out:
        for k, row in enumerate(pool.imap(analyse, todo), 1):
            row["truth"] = answers[row["campaign"]]
            out.write(json.dumps(row) + "\n")
            out.flush()
            print(f"[{k}/{len(todo)}] {row['campaign']}: {row['found']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
