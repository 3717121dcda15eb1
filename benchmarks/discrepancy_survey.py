"""Run the discrepancy tool blind on synthetic campaigns with concealed effects and score it,
side by side with PySINDy on the same campaigns.

    .venv/bin/python benchmarks/discrepancy_survey.py [--seeds 100:130] [--drop-seeds 200:230]
                                                      [--jobs 2] [--out DIR]

Torque-driven campaigns (transparency_ros.synth.campaign): 10 trials x 6 s at 500 Hz of a
pendulum on an actuator. Drop-test campaigns (transparency_ros.synth.drop_campaign): 6 drop
heights of one actuator, as bags. Hidden effects are drawn from the seed: single effects, pairs,
none, and one effect outside the library. Both methods see the data and the nominal model only;
the labels are read afterwards to score recall and precision of effect names, false findings on
effect-free campaigns, outside-the-library effects, parameter error, held-out improvement and
run time. PySINDy's libraries and how its terms are read as effects: benchmarks/sindy_baseline.py.
Campaigns run in ``--jobs`` processes. Writes benchmarks/results/discrepancy_survey.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))


@dataclass
class Row:
    seed: int
    hidden: dict[str, dict[str, float]]  # the labels
    found: dict[str, dict[str, float]]  # effect -> fitted parameters
    unexplained: bool
    seconds: float
    gain: float  # 1 - final / nominal held-out RMSE


def torque_campaign(seed: int) -> tuple[Row, Row]:
    from sindy_baseline import run_sindy  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy.discover import discover  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.model import Trial, load_nominal  # noqa: PLC0415
    from transparency_ros.synth.campaign import write_campaign  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        d = write_campaign(Path(tmp) / str(seed), seed)
        trials = [
            Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
            for f in sorted((d / "data").glob("*.csv"))
        ]
        nominal = load_nominal(d / "nominal.yaml")
        hidden = json.loads((d / "labels.json").read_text())["hidden"]
    started = time.perf_counter()
    report = discover(nominal, trials)
    tool = _tool_row(seed, hidden, report, time.perf_counter() - started)
    started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s_found, s_rmse, s_nominal = run_sindy(nominal, trials)
    seconds = time.perf_counter() - started
    return tool, Row(
        seed, hidden, {key: {} for key in s_found}, False, seconds, 1 - s_rmse / s_nominal
    )


def drop_campaign(seed: int) -> tuple[Row, Row]:
    from sindy_baseline import run_sindy_drop  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy.discover import Discoverer  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.drop import (  # noqa: PLC0415
        DropProblem,
        load_drop_nominal,
        load_drop_trial,
    )
    from transparency_ros.bag.reader import find_bags  # noqa: PLC0415
    from transparency_ros.synth.drop_campaign import write_drop_campaign  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        d = write_drop_campaign(Path(tmp) / str(seed), seed)
        trials = [load_drop_trial(b) for b in find_bags([str(d / "bags")])]
        hidden = json.loads((d / "labels.json").read_text())["hidden"]
    started = time.perf_counter()
    problem = DropProblem(trials, load_drop_nominal(None, trials))
    report = Discoverer(problem).run()
    tool = _tool_row(seed, hidden, report, time.perf_counter() - started)
    started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s_found, s_rmse, s_nominal = run_sindy_drop(problem)
    seconds = time.perf_counter() - started
    return tool, Row(
        seed, hidden, {key: {} for key in s_found}, False, seconds, 1 - s_rmse / s_nominal
    )


def _tool_row(seed: int, hidden: dict[str, Any], report: Any, seconds: float) -> Row:
    return Row(
        seed,
        hidden,
        {f.effect: f.parameters for f in report.findings},
        bool(report.unexplained),
        seconds,
        1 - report.final_heldout_rmse / report.heldout_rmse_nominal,
    )


def survey(kind: str, seeds: range, jobs: int) -> tuple[list[Row], list[Row]]:
    work = torque_campaign if kind == "torque" else drop_campaign
    tool, sindy = [], []
    with Pool(jobs) as pool:
        for a, b in pool.imap(work, seeds):
            tool.append(a)
            sindy.append(b)
            print(
                kind,
                a.seed,
                sorted(a.hidden),
                "tool:",
                sorted(a.found),
                "unexplained" if a.unexplained else "",
                f"held-out {a.gain:.0%} lower, {a.seconds:.1f}s | sindy:",
                sorted(b.found),
                f"{b.seconds:.1f}s",
                flush=True,
            )
    return tool, sindy


def score(rows: list[Row], outside: str) -> dict[str, str]:
    library = [r for r in rows if r.hidden and outside not in r.hidden]
    single = [r for r in library if len(r.hidden) == 1]
    correct = sum(len(set(r.hidden) & set(r.found)) for r in library)
    named = sum(len(r.found) for r in library)
    none = [r for r in rows if not r.hidden]
    out = [r for r in rows if outside in r.hidden]
    gains = [r.gain for r in library if set(r.hidden) & set(r.found)]
    times = [r.seconds for r in rows]
    errors = [
        abs(r.found[e][k] - v) / abs(v)
        for r in library
        for e in set(r.hidden) & set(r.found)
        for k, v in r.hidden[e].items()
        if k in r.found[e] and v != 0
    ]
    return {
        "single-effect recall": f"{sum(set(r.hidden) <= set(r.found) for r in single)}"
        f"/{len(single)}",
        "recall, all library effects": f"{correct}/{sum(len(r.hidden) for r in library)}",
        "precision of named effects": f"{correct}/{named}",
        "false findings on effect-free campaigns": f"{sum(len(r.found) for r in none)} in "
        f"{len(none)}",
        "outside-library effect, no label forced": f"{sum(not r.found for r in out)}/{len(out)}",
        "parameter error of correctly named effects, median / max": (
            f"{np.median(errors):.0%} / {max(errors):.0%} ({len(errors)} values)"
            if errors
            else "- (no parameters)"
        ),
        "held-out RMSE down, where a hidden effect was named (median)": (
            f"{np.median(gains):.0%}" if gains else "-"
        ),
        "of those campaigns, held-out RMSE down >= 50 %": f"{sum(g >= 0.5 for g in gains)}"
        f"/{len(gains)}",
        "run time per campaign [s], median / max": f"{np.median(times):.1f} / {max(times):.1f}",
    }


def table(title: str, a: dict[str, str], b: dict[str, str]) -> list[str]:
    return [
        title,
        "",
        "| measure | this tool | PySINDy |",
        "|---|---|---|",
        *[f"| {name} | {a[name]} | {b[name]} |" for name in a],
        "",
    ]


def main() -> int:
    from transparency_ros.synth.campaign import OUTSIDE  # noqa: PLC0415
    from transparency_ros.synth.drop_campaign import OUTSIDE as DROP_OUTSIDE  # noqa: PLC0415

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100:130", help="torque-driven: first:last+1")
    parser.add_argument("--drop-seeds", default="200:230", help="drop tests: first:last+1")
    parser.add_argument("--jobs", type=int, default=2, help="campaigns analysed at once")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    lines = []
    started = time.perf_counter()
    for kind, text, outside in (
        ("torque", args.seeds, OUTSIDE),
        ("drop", args.drop_seeds, DROP_OUTSIDE),
    ):
        first, last = (int(x) for x in text.split(":"))
        if last <= first:
            continue
        tool, sindy = survey(kind, range(first, last), args.jobs)
        what = (
            "torque-driven campaigns (10 trials x 6 s at 500 Hz)"
            if kind == "torque"
            else "drop-test campaigns (6 heights of one actuator)"
        )
        lines += table(
            f"Seeds {first}-{last - 1}: {len(tool)} {what}, this tool and PySINDy on the same "
            "campaigns",
            score(tool, outside),
            score(sindy, outside),
        )
    lines.append(
        f"{args.jobs} processes, {time.perf_counter() - started:.0f} s in all "
        "(`.venv/bin/python benchmarks/discrepancy_survey.py`)."
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "discrepancy_survey.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
