"""``transparency feelcage``: Table 2 of the paper (feel -> process -> act, 4 x 3 cells)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from transparency_ros.analysis.feelcage_sim import (
    ACTUATORS,
    PAPER_TABLE2,
    load_setup,
    steady_sweep,
    table2,
    time_to_cage,
)
from transparency_ros.core.config import get_actuator


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "feelcage",
        help="reproduce Table 2 (feel-cage task): outcome and timings per actuator and ball",
        description=(
            "Run the feel-cage task for the 4 actuators x 3 balls of Table 2 with one geometry "
            "and one set of ball parameters (config/feel_cage.yaml): measure e_s from a steady "
            "1 rev/s sweep, strike the ball, detect at e_s + epsilon, wait t_process, turn CW "
            "at 10.5 V to the cage angle. --engine core runs the project's cores (physics, "
            "estimator, behavior) in one process at the driver's 1 kHz sampling."
        ),
    )
    p.add_argument(
        "--engine",
        choices=["core"],
        default="core",
        help="core: the ROS-free cores (the real-node engine is not available yet)",
    )
    p.add_argument("--config", metavar="YAML", help="use this feel_cage.yaml")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=run)


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.1f}"


def run(args: argparse.Namespace) -> int:
    setup = load_setup(args.config)
    results = table2(setup)
    sweeps = {name: steady_sweep(get_actuator(name), setup) for name in ACTUATORS}
    e_s = {name: sw.steady_error_rad for name, sw in sweeps.items()}
    to_cage = {name: time_to_cage(name, setup, sweeps[name]) for name in ACTUATORS}
    rows: list[dict[str, Any]] = []
    for ball in setup.balls:
        for i, actuator in enumerate(ACTUATORS):
            r = results[(ball, actuator)]
            rows.append({
                "ball": ball, "actuator": actuator, "outcome": r.outcome.value,
                "paper": PAPER_TABLE2.get(ball, ("?",) * 4)[i],
                "t_feel_s": r.t_feel_s, "t_process_s": r.t_process_s, "t_act_s": r.t_act_s,
                "t_total_s": r.t_total_s, "t_budget_s": r.t_budget_s,
                "t_to_cage_s": to_cage[actuator],
            })  # fmt: skip
    matches = sum(row["outcome"] == row["paper"] for row in rows)
    if args.json:
        json.dump(
            {
                "engine": args.engine,
                "steady_error_rad": e_s,
                "time_to_cage_s": to_cage,
                "cells": rows,
                "matches_paper": matches,
            },
            sys.stdout,
            indent=2,
        )
        print()
        return 0
    print("e_s at 1 rev/s [rad]: " + ", ".join(f"{k} {v:.3f}" for k, v in e_s.items()))
    print(f"{'ball':<9} " + " ".join(f"{a:<14}" for a in ACTUATORS))
    for ball in setup.balls:
        cells = [r for r in rows if r["ball"] == ball]
        print(
            f"{ball:<9} "
            + " ".join(
                f"{c['outcome'] + ('' if c['outcome'] == c['paper'] else ' (!)'):<14}"
                for c in cells
            )
        )
    print(f"\n{matches}/12 cells as in the paper ((!) marks a difference)")
    print(
        f"\n{'cell':<16} {'t_feel':>7} {'t_proc':>7} {'t_act':>7} {'t_total':>8} "
        f"{'t_budget':>9} {'to cage':>8}  [ms]  (to cage: the act time the actuator needs)"
    )
    for c in rows:
        print(
            f"{c['ball'] + '/' + c['actuator']:<16} {_ms(c['t_feel_s']):>7} "
            f"{_ms(c['t_process_s']):>7} {_ms(c['t_act_s']):>7} {_ms(c['t_total_s']):>8} "
            f"{_ms(c['t_budget_s']):>9} {_ms(c['t_to_cage_s']):>8}"
        )
    return 0
