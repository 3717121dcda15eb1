"""Run the discrepancy tool blind on synthetic campaigns with concealed effects and score it,
side by side with PySINDy on the same campaigns.

    .venv/bin/python benchmarks/discrepancy_survey.py [--seeds 100:130] [--out DIR]

Each seed writes a campaign (10 trials x 6 s at 500 Hz) with hidden effects drawn from the seed
(transparency_ros.synth.campaign); both methods see the data and the nominal model only; the
labels are read afterwards to score: recall and precision of effect names, false findings on
effect-free campaigns, outside-the-library effects, held-out improvement and run time.
PySINDy's library and how its terms are read as effects: benchmarks/sindy_baseline.py. Writes a
markdown table to benchmarks/results/discrepancy_survey.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from transparency_ros.analysis.discrepancy.discover import discover
from transparency_ros.analysis.discrepancy.model import Trial, load_nominal
from transparency_ros.synth.campaign import OUTSIDE, write_campaign

sys.path.insert(0, str(Path(__file__).parent))
from sindy_baseline import run_sindy

Row = tuple[int, list[str], list[str], bool, float, float]  # seed, hidden, found, unexpl., s, gain


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100:130", help="first:last+1")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    first, last = (int(x) for x in args.seeds.split(":"))
    tool: list[Row] = []
    sindy: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(first, last):
            d = write_campaign(Path(tmp) / str(seed), seed)
            trials = [
                Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
                for f in sorted((d / "data").glob("*.csv"))
            ]
            nominal = load_nominal(d / "nominal.yaml")
            hidden = sorted(json.loads((d / "labels.json").read_text())["hidden"])
            started = time.perf_counter()
            report = discover(nominal, trials)
            seconds = time.perf_counter() - started
            found = [f.effect for f in report.findings]
            gain = 1 - report.final_heldout_rmse / report.heldout_rmse_nominal
            tool.append((seed, hidden, found, bool(report.unexplained), seconds, gain))
            started = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s_found, s_rmse, s_nominal = run_sindy(nominal, trials)
            s_seconds = time.perf_counter() - started
            sindy.append((seed, hidden, s_found, False, s_seconds, 1 - s_rmse / s_nominal))
            print(
                seed,
                hidden,
                "tool:",
                found,
                "unexplained" if report.unexplained else "",
                f"{seconds:.1f}s | sindy:",
                s_found,
                f"{s_seconds:.1f}s",
                flush=True,
            )
    a, b = score(tool), score(sindy)
    table = [
        f"Discrepancy survey, seeds {first}-{last - 1}: {len(tool)} campaigns of 10 trials, "
        "this tool and PySINDy on the same campaigns",
        "",
        "| measure | this tool | PySINDy |",
        "|---|---|---|",
    ] + [f"| {name} | {a[name]} | {b[name]} |" for name in a]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "discrepancy_survey.md").write_text("\n".join(table) + "\n")
    print("\n".join(table))
    return 0


def score(rows: list[Row]) -> dict[str, str]:
    library = [(h, f, g) for _, h, f, _, _, g in rows if h and OUTSIDE not in h]
    single = [(h, f) for h, f, _ in library if len(h) == 1]
    correct = sum(len(set(h) & set(f)) for h, f, _ in library)
    named = sum(len(f) for h, f, _ in library)
    none = [f for _, h, f, _, _, _ in rows if not h]
    outside = [f for _, h, f, _, _, _ in rows if OUTSIDE in h]
    gains = [g for h, f, g in library if set(h) & set(f)]
    times = [r[4] for r in rows]
    median_gain = f"{np.median(gains):.0%}" if gains else "-"
    halved = f"{sum(g >= 0.5 for g in gains)}/{len(gains)}"
    return {
        "single-effect recall": f"{sum(h[0] in f for h, f in single) / max(1, len(single)):.0%}"
        f" ({len(single)} campaigns)",
        "recall, all library effects": f"{correct}/{sum(len(h) for h, _, _ in library)}",
        "precision of named effects": f"{correct}/{named}",
        "false findings on effect-free campaigns": f"{sum(map(len, none))} in {len(none)}",
        "outside-library effect, no label forced": f"{sum(not f for f in outside)}/{len(outside)}",
        "held-out RMSE down, where a hidden effect was named (median)": median_gain,
        "of those campaigns, held-out RMSE down >= 50 %": halved,
        "run time per campaign [s], median / max": f"{np.median(times):.1f} / {max(times):.1f}",
    }


if __name__ == "__main__":
    raise SystemExit(main())
