"""Time per sample of the robots' generalized-momentum observer against the number of joints.

    .venv/bin/python benchmarks/momentum_observer.py [--joints 1 2 6 12] [--samples N] [--out DIR]

One Python process, one observer (:class:`RobotMomentumObserver` on a URDF chain of n revolute
joints, Pinocchio's M(q), C(q, q') and g(q)), fed one sample at a time through ``update`` as the
node does; the motion is a smooth random one. The goal: a 12-joint robot at 1 kHz, i.e. well
under 1 ms per sample, leaving the rest of the period to the node. Writes
benchmarks/results/momentum_observer.md and .json.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

from transparency_ros.core.momentum_observer import RobotMomentumObserver
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.synth.robots import chain_urdf

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_results


def measure(joints: int, samples: int) -> dict[str, float]:
    model = RobotModel.from_urdf(chain_urdf(joints))
    observer = RobotMomentumObserver(model, gain_per_s=50.0)
    rng = np.random.default_rng(joints)
    t = np.arange(samples) * 1e-3
    phase = rng.uniform(0, 2 * np.pi, joints)
    q = 0.5 * np.sin(2 * np.pi * 0.5 * t[:, None] + phase)
    v = 0.5 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t[:, None] + phase)
    tau = rng.normal(0, 1.0, (samples, joints))
    stamps = np.arange(samples, dtype=np.int64) * 1_000_000
    took = np.empty(samples)
    for k in range(samples):
        start = time.perf_counter_ns()
        observer.update(int(stamps[k]), q[k], v[k], tau[k])
        took[k] = time.perf_counter_ns() - start
    took_us = took[100:] / 1e3  # after warm-up
    return {
        "joints": joints,
        "median_us": float(np.median(took_us)),
        "p99_us": float(np.percentile(took_us, 99)),
        "max_us": float(np.max(took_us)),
        "share_of_1khz_period": float(np.median(took_us) / 1000.0),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--joints", type=int, nargs="+", default=[1, 2, 6, 12])
    parser.add_argument("--samples", type=int, default=20000)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    rows = [measure(n, args.samples) for n in args.joints]
    lines = [
        f"Generalized-momentum observer, one sample at a time (`update`), {args.samples} samples "
        f"per size, Python {platform.python_version()}, one process",
        "",
        "| joints | median [us] | p99 [us] | max [us] | median share of a 1 kHz period |",
        "|---|---|---|---|---|",
        *(
            f"| {r['joints']} | {r['median_us']:.1f} | {r['p99_us']:.1f} | {r['max_us']:.0f} "
            f"| {r['share_of_1khz_period']:.1%} |"
            for r in rows
        ),
        "",
        "`.venv/bin/python benchmarks/momentum_observer.py`",
    ]
    write_results(args.out, "momentum_observer", lines, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
