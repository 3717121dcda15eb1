"""Run the discrepancy tool blind on synthetic campaigns with concealed effects and score it.

    .venv/bin/python benchmarks/discrepancy_survey.py [--seeds 100:130] [--out DIR]

Each seed writes a campaign (10 trials x 6 s at 500 Hz) with hidden effects drawn from the seed
(transparency_ros.synth.campaign); the tool sees the data and the nominal model only; the labels
are read afterwards to score: recall and precision of effect names, false findings on effect-free
campaigns, outside-the-library effects reported as unexplained, and run time. Writes a markdown
table to benchmarks/results/discrepancy_survey.md. (The PySINDy baseline is not in it yet.)
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from transparency_ros.analysis.discrepancy.discover import discover
from transparency_ros.analysis.discrepancy.model import Trial, load_nominal
from transparency_ros.synth.campaign import OUTSIDE, write_campaign


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100:130", help="first:last+1")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    first, last = (int(x) for x in args.seeds.split(":"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(first, last):
            d = write_campaign(Path(tmp) / str(seed), seed)
            trials = [
                Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
                for f in sorted((d / "data").glob("*.csv"))
            ]
            started = time.perf_counter()
            report = discover(load_nominal(d / "nominal.yaml"), trials)
            seconds = time.perf_counter() - started
            hidden = sorted(json.loads((d / "labels.json").read_text())["hidden"])
            found = [f.effect for f in report.findings]
            rows.append((seed, hidden, found, bool(report.unexplained), seconds))
            print(
                seed,
                hidden,
                found,
                "unexplained" if report.unexplained else "",
                f"{seconds:.1f}s",
                flush=True,
            )
    library_hidden = [(h, f) for _, h, f, _, _ in rows if h and OUTSIDE not in h]
    single = [(h, f) for h, f in library_hidden if len(h) == 1]
    recall_single = sum(h[0] in f for h, f in single) / max(1, len(single))
    all_found = sum(len(f) for h, f in library_hidden)
    correct = sum(len(set(h) & set(f)) for h, f in library_hidden)
    total_hidden = sum(len(h) for h, f in library_hidden)
    none = [(f, u) for _, h, f, u, _ in rows if not h]
    outside = [(f, u) for _, h, f, u, _ in rows if OUTSIDE in h]
    times = [r[4] for r in rows]
    table = [
        f"Discrepancy survey, seeds {first}-{last - 1} ({len(rows)} campaigns of 10 trials)",
        "",
        "| measure | value |",
        "|---|---|",
        f"| single-effect recall | {recall_single:.0%} ({len(single)} campaigns) |",
        f"| recall, all library effects | {correct}/{total_hidden} |",
        f"| precision of named effects | {correct}/{all_found} |",
        f"| false findings on effect-free campaigns | {sum(len(f) for f, _ in none)} "
        f"in {len(none)} |",
        f"| outside-library effect reported unexplained, none forced | "
        f"{sum(u and not f for f, u in outside)}/{len(outside)} |",
        f"| run time per campaign [s] | median {np.median(times):.1f}, max {max(times):.1f} |",
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "discrepancy_survey.md").write_text("\n".join(table) + "\n")
    print("\n".join(table))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
