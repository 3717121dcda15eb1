"""How the discrepancy tool's cost grows with the campaign: wall time and peak memory for 10-,
30- and 100-trial campaigns, this tool and PySINDy on the same campaigns.

    .venv/bin/python benchmarks/discrepancy_scaling.py [--trials 10,30,100] [--drop-trials 10,30]
                                                       [--out DIR]

Torque-driven: generator campaigns of N trials x 6 s at 500 Hz with cogging and a sensor delay
hidden (the README's worked example, seed 7). Drop tests: N drop heights from 0.05 to 0.8 m of a
T2822 with backlash and a torque offset hidden (a pair: the costliest path, where candidates
are also fitted two at a time). Each analysis runs in a fresh process (spawned), so its peak
resident memory (ru_maxrss, imports included) is its own; the campaign is written and loaded
before the clock starts. Writes benchmarks/results/discrepancy_scaling.md and .json.
"""

from __future__ import annotations

import argparse
import multiprocessing
import resource
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from _results import write_results

sys.path.insert(0, str(Path(__file__).parent))

TORQUE_HIDDEN = ["cogging", "sensor_delay"]
DROP_HIDDEN = ["backlash", "torque_offset"]


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux


def torque(n: int, method: str) -> dict[str, Any]:
    from sindy_baseline import run_sindy  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy.discover import discover  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.model import Trial, load_nominal  # noqa: PLC0415
    from transparency_ros.synth.campaign import write_campaign  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        d = write_campaign(Path(tmp) / "c", 7, trials=n, hidden=TORQUE_HIDDEN)
        trials = [
            Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
            for f in sorted((d / "data").glob("*.csv"))
        ]
        nominal = load_nominal(d / "nominal.yaml")
    started = time.perf_counter()
    if method == "tool":
        found = [f.effect for f in discover(nominal, trials).findings]
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found = run_sindy(nominal, trials)[0]
    return {"seconds": time.perf_counter() - started, "peak_mb": _peak_mb(), "found": found}


def drop(n: int, method: str) -> dict[str, Any]:
    from sindy_baseline import run_sindy_drop  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy.discover import Discoverer  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.drop import (  # noqa: PLC0415
        DropProblem,
        load_drop_nominal,
        load_drop_trial,
    )
    from transparency_ros.bag.reader import find_bags  # noqa: PLC0415
    from transparency_ros.synth.drop_campaign import write_drop_campaign  # noqa: PLC0415

    heights = [float(h) for h in np.linspace(0.05, 0.8, n)]
    with tempfile.TemporaryDirectory() as tmp:
        d = write_drop_campaign(
            Path(tmp) / "c", 214, hidden=DROP_HIDDEN, actuator="T2822", heights=heights
        )
        trials = [load_drop_trial(b) for b in find_bags([str(d / "bags")])]
    started = time.perf_counter()
    problem = DropProblem(trials, load_drop_nominal(None, trials))
    if method == "tool":
        found = [f.effect for f in Discoverer(problem).run().findings]
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found = run_sindy_drop(problem)[0]
    return {"seconds": time.perf_counter() - started, "peak_mb": _peak_mb(), "found": found}


def _run(job: tuple[str, int, str]) -> dict[str, Any]:
    kind, n, method = job
    out = (torque if kind == "torque" else drop)(n, method)
    return {"kind": kind, "trials": n, "method": method, **out}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", default="10,30,100", help="torque-driven campaign sizes")
    parser.add_argument(
        "--drop-trials",
        default="10,30",
        help="drop-test campaign sizes (100 takes about 5 min, most of it writing the bags)",
    )
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    sizes = {
        "torque": [int(x) for x in args.trials.split(",") if x],
        "drop": [int(x) for x in args.drop_trials.split(",") if x],
    }
    jobs = [(k, n, m) for k in ("torque", "drop") for n in sizes[k] for m in ("tool", "pysindy")]
    rows = []
    started = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    for job in jobs:
        with ctx.Pool(1, maxtasksperchild=1) as pool:  # a fresh process: its own peak memory
            row = pool.apply(_run, (job,))
        rows.append(row)
        print(
            f"{row['kind']:6} {row['trials']:4} trials {row['method']:8} "
            f"{row['seconds']:7.1f} s {row['peak_mb']:6.0f} MB found {row['found']}",
            flush=True,
        )
    lines = [
        "Discrepancy analysis, wall time and peak memory (one process per analysis, 2 cores; "
        f"torque-driven: {' + '.join(TORQUE_HIDDEN)} hidden; drop tests: "
        f"{' + '.join(DROP_HIDDEN)} hidden)",
        "",
        "| recording | trials | this tool [s] | this tool peak [MB] | named | PySINDy [s] "
        "| PySINDy peak [MB] |",
        "|---|---|---|---|---|---|---|",
    ]
    by = {(r["kind"], r["trials"], r["method"]): r for r in rows}
    for kind in ("torque", "drop"):
        for n in sizes[kind]:
            tool, peer = by[kind, n, "tool"], by[kind, n, "pysindy"]
            named = ", ".join(tool["found"]) or "-"
            lines.append(
                f"| {'torque-driven' if kind == 'torque' else 'drop tests'} | {n} "
                f"| {tool['seconds']:.1f} | {tool['peak_mb']:.0f} | {named} "
                f"| {peer['seconds']:.1f} | {peer['peak_mb']:.0f} |"
            )
    lines += [
        "",
        f"{time.perf_counter() - started:.0f} s in all "
        "(`.venv/bin/python benchmarks/discrepancy_scaling.py`).",
    ]
    write_results(args.out, "discrepancy_scaling", lines, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
