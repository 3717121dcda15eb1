"""``transparency feelcage``: Table 2 of the paper (feel -> process -> act, 4 x 3 cells)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from transparency_ros.analysis.feelcage_sim import (
    ACTUATORS,
    PAPER_TABLE2,
    FeelCageSetup,
    load_setup,
    simulate_cell,
    steady_sweep,
    time_to_cage,
)
from transparency_ros.core import strict_json
from transparency_ros.core.config import get_actuator
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.feel_cage import TrialRecord


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "feelcage",
        help="reproduce Table 2 (feel-cage task): outcome and timings per actuator and ball",
        description=(
            "Run the feel-cage task for the 4 actuators x 3 balls of Table 2 with one geometry "
            "and one set of ball parameters (config/feel_cage.yaml): measure e_s from a steady "
            "1 rev/s sweep, strike the ball, detect at e_s + epsilon, wait t_process, turn CW "
            "at 10.5 V to the cage angle. --engine ros runs the real nodes (actuator_driver "
            "with the simulated actuator striking the ball, contact_estimator, "
            "feel_cage_behavior), each its own process, on loopback; about 12 s per cell. "
            "--engine core runs the same cores (physics, estimator, behavior) in one process "
            "at the driver's 1 kHz sampling, in a few seconds for all cells."
        ),
    )
    p.add_argument(
        "--engine",
        choices=["ros", "core"],
        default="ros",
        help="ros: through the real nodes (default); core: the ROS-free cores, fast",
    )
    p.add_argument(
        "--actuators",
        default=",".join(ACTUATORS),
        help="comma-separated subset of the actuators (default: all four)",
    )
    p.add_argument(
        "--balls",
        default="rubber,lacrosse,bocce",
        help="comma-separated subset of the balls (default: all three)",
    )
    p.add_argument("--config", metavar="YAML", help="use this feel_cage.yaml")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=run)


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.1f}"


def _subset(text: str, allowed: Sequence[str], what: str) -> list[str]:
    chosen = [item.strip() for item in text.split(",") if item.strip()]
    unknown = [item for item in chosen if item not in allowed]
    if unknown or not chosen:
        raise ConfigError(f"--{what}: {unknown or text!r} not in {list(allowed)}")
    return [item for item in allowed if item in chosen]  # in table order


Cells = dict[tuple[str, str], TrialRecord]


def _run_cells(
    engine: str, setup: FeelCageSetup, actuators: list[str], balls: list[str]
) -> tuple[Cells, dict[tuple[str, str], float | None], dict[str, float], dict[str, float]]:
    """Records per (ball, actuator), the time from the onset sample to the act torque on the
    motor per (ball, actuator) (core: t_process), e_s per actuator, and (ros) the error noise
    per actuator."""
    records: Cells = {}
    torque: dict[tuple[str, str], float | None] = {}
    e_s: dict[str, float] = {}
    noise: dict[str, float] = {}
    if engine == "core":
        for name in actuators:
            sweep = steady_sweep(get_actuator(name), setup)
            e_s[name] = sweep.steady_error_rad
            for ball in balls:
                records[(ball, name)] = record = simulate_cell(name, ball, setup, sweep)
                torque[(ball, name)] = record.t_process_s
        return records, torque, e_s, noise
    from transparency_ros.ros.feelcage_run import run_cell  # noqa: PLC0415 - needs rclpy

    total, done, rate = len(actuators) * len(balls), 0, float("inf")
    for name in actuators:
        for ball in balls:
            done += 1
            print(f"[{done}/{total}] {ball} / {name} through the nodes ...", file=sys.stderr,
                  flush=True)  # fmt: skip
            cell = run_cell(name, ball, setup)
            for line in cell.node_warnings:  # a stalled loop, a device fault: beside its cell
                print(f"  {line}", file=sys.stderr)
            records[(ball, name)] = cell.record
            torque[(ball, name)] = cell.t_torque_s
            e_s[name] = max(e_s.get(name, 0.0), cell.steady_error_rad)
            noise[name] = max(noise.get(name, 0.0), cell.error_noise_rad)
            rate = min(rate, cell.sample_rate_hz)
    print(f"lowest /estimated_effort rate while measuring e_s: {rate:.0f} Hz", file=sys.stderr)
    return records, torque, e_s, noise


def run(args: argparse.Namespace) -> int:
    setup = load_setup(args.config)
    actuators = _subset(args.actuators, ACTUATORS, "actuators")
    balls = _subset(args.balls, tuple(setup.balls), "balls")
    results, torque, e_s, noise = _run_cells(args.engine, setup, actuators, balls)
    to_cage = {name: time_to_cage(name, setup) for name in actuators}
    rows: list[dict[str, Any]] = []
    for ball in balls:
        for actuator in actuators:
            r = results[(ball, actuator)]
            rows.append({
                "ball": ball, "actuator": actuator, "outcome": r.outcome.value,
                "paper": PAPER_TABLE2.get(ball, ("?",) * 4)[ACTUATORS.index(actuator)],
                "t_feel_s": r.t_feel_s, "t_process_s": r.t_process_s,
                "t_torque_s": torque[(ball, actuator)], "t_act_s": r.t_act_s,
                "t_total_s": r.t_total_s, "t_budget_s": r.t_budget_s,
                "t_to_cage_s": to_cage[actuator],
            })  # fmt: skip
    matches = sum(row["outcome"] == row["paper"] for row in rows)
    if args.json:
        strict_json.dump(
            {
                "engine": args.engine,
                "steady_error_rad": e_s,
                "error_noise_rad": noise,
                "time_to_cage_s": to_cage,
                "cells": rows,
                "matches_paper": matches,
            },
            sys.stdout,
        )
        return 0
    print(f"engine: {args.engine}")
    print("e_s at 1 rev/s [rad]: " + ", ".join(f"{k} {v:.3f}" for k, v in e_s.items()))
    if noise:
        print("error noise (std) [rad]: " + ", ".join(f"{k} {v:.4f}" for k, v in noise.items()))
    print(f"{'ball':<9} " + " ".join(f"{a:<14}" for a in actuators))
    for ball in balls:
        cells = [r for r in rows if r["ball"] == ball]
        print(
            f"{ball:<9} "
            + " ".join(
                f"{c['outcome'] + ('' if c['outcome'] == c['paper'] else ' (!)'):<14}"
                for c in cells
            )
        )
    print(f"\n{matches}/{len(rows)} cells as in the paper ((!) marks a difference)")
    print(
        f"\n{'cell':<16} {'t_feel':>7} {'t_proc':>7} {'t_torque':>8} {'t_act':>7} {'t_total':>8} "
        f"{'t_budget':>9} {'to cage':>8}  [ms]\n(t_torque: from the onset sample to the act torque "
        "on the motor; to cage: the act time the actuator needs)"
    )
    for c in rows:
        print(
            f"{c['ball'] + '/' + c['actuator']:<16} {_ms(c['t_feel_s']):>7} "
            f"{_ms(c['t_process_s']):>7} {_ms(c['t_torque_s']):>8} {_ms(c['t_act_s']):>7} "
            f"{_ms(c['t_total_s']):>8} {_ms(c['t_budget_s']):>9} {_ms(c['t_to_cage_s']):>8}"
        )
    return 0
