"""Driver loop benchmark: achieved rate and cycle jitter of `actuator_driver` on the virtual bus.

Each case starts the real executable as its own process (what `ros2 run` does) with the
simulated actuator, lets it warm up, then measures for --seconds:
* the loop's own figures, read from its /diagnostics (rate, jitter p50/p99/max over the last
  5000 cycles; overruns and missed replies counted within the window);
* /joint_states messages delivered to a subscriber in this process (drops show here).
Every process runs on loopback with a domain ID of its own. Results: a table on stdout, JSON and
Markdown in benchmarks/results/.

A second table: several motors in one process (``motor_ids``, issue 18) at 1 kHz, 1, 2, 6 and 12
simulated MIT motors on one bus, and 12 on 4 buses (3 each, as a robot's legs would be wired);
the simulated motors run in the same process (python-can's virtual bus does not leave it), so
their physics is part of the load measured.

    .venv/bin/python benchmarks/driver_loop.py [--rates 1000 2000] [--seconds 10]
        [--motors 1 2 6 12]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

from transparency_ros.ros.harness import Listener, start_node, stop_node

RESULTS = Path(__file__).parent / "results"


def measure(
    protocol: str, rate_hz: float, seconds: float, warmup_s: float, *, motors: int = 0,
    buses: int = 1,
) -> dict[str, Any]:  # fmt: skip
    """One process; ``motors`` > 0: that many motors in one loop (motor_ids) on ``buses``."""
    params: dict[str, Any] = {
        "protocol": protocol, "publish_rate_hz": rate_hz, "command_timeout_s": 60.0,
    }  # fmt: skip
    if motors:
        params["motor_ids"] = list(range(1, motors + 1))
        params["channels"] = [f"bench_bus_{i % buses}" for i in range(motors)]
    proc = start_node("actuator_driver", params, extra=["--log-level", "warn"], quiet=True)
    received = [0]
    diagnostics: list[dict[str, str]] = []
    wanted = "actuator_driver: loop" if motors else ""
    missed_key = "missed_replies_total"
    try:
        with Listener("driver_loop_bench") as node:
            node.create_subscription(
                JointState,
                "/joint_states",
                lambda _m: received.__setitem__(0, received[0] + 1),
                1000,
            )
            node.create_subscription(
                DiagnosticArray,
                "/diagnostics",
                lambda m: diagnostics.append(summary(m, wanted, missed_key)),
                10,
            )
            deadline = time.monotonic() + 20.0
            while received[0] == 0 and time.monotonic() < deadline:
                time.sleep(0.05)
            if received[0] == 0 and not motors:
                raise RuntimeError(f"{protocol} @ {rate_hz} Hz: no /joint_states within 20 s")
            time.sleep(warmup_s)
            first = diagnostics[-1]
            start_count, start = received[0], time.monotonic()
            time.sleep(seconds)
            delivered = (received[0] - start_count) / (time.monotonic() - start)
            time.sleep(1.2)  # one more diagnostics period covering the window
            last = diagnostics[-1]
    finally:
        stop_node(proc)
    return {
        "protocol": protocol,
        "motors": motors or 1,
        "buses": buses,
        "one_motor_path": not motors,
        "rate_hz": rate_hz,
        "loop_rate_hz": float(last["loop_rate_hz"]),
        "delivered_hz": delivered,
        "jitter_p50_us": float(last["jitter_p50_us"]),
        "jitter_p99_us": float(last["jitter_p99_us"]),
        "jitter_max_us": float(last["jitter_max_us"]),
        "cycle_cpu_p50_us": float(last.get("cycle_cpu_p50_us", "nan")),
        "cycle_cpu_p99_us": float(last.get("cycle_cpu_p99_us", "nan")),
        # counted within the measurement window (diagnostics at its start and end)
        "overruns": int(last["overruns"]) - int(first["overruns"]),
        "missed_replies": int(last["missed_replies_total"]) - int(first["missed_replies_total"]),
        "faulted_motors": int(last["faulted"]),
        "exit_code": proc.returncode,
    }


def summary(msg: DiagnosticArray, loop_name: str, missed_key: str) -> dict[str, str]:
    """The loop's figures of one /diagnostics message, with the motors' missed replies summed."""
    statuses = [{kv.key: kv.value for kv in s.values} for s in msg.status]
    named = {s.name: values for s, values in zip(msg.status, statuses, strict=True)}
    figures = dict(named[loop_name]) if loop_name else dict(statuses[0])
    figures[missed_key] = str(sum(int(v.get(missed_key, 0)) for v in statuses))
    motors = [s for s in msg.status if s.name != loop_name]
    figures["faulted"] = str(sum(s.level == DiagnosticStatus.ERROR for s in motors))
    return figures


def motors_table(args: argparse.Namespace) -> list[dict[str, Any]]:
    cases = [(n, 1, 1000.0) for n in args.motors]
    if 12 in args.motors:
        cases += [(12, 4, 1000.0), (12, 4, 500.0)]
    rows = []
    for n, buses, rate in cases:
        print(f"measuring {n} motors on {buses} bus(es) at {rate:g} Hz ...", flush=True)
        rows.append(measure("mit", rate, args.seconds, args.warmup, motors=n, buses=buses))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--rates", type=float, nargs="+", default=[1000.0, 2000.0])
    parser.add_argument("--protocols", nargs="+", default=["mit", "odrive", "moteus"])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--warmup", type=float, default=2.0)
    parser.add_argument("--motors", type=int, nargs="*", default=[1, 2, 6, 12])
    args = parser.parse_args()
    rows = []
    for protocol in args.protocols:
        for rate in args.rates:
            print(f"measuring {protocol} at {rate:g} Hz for {args.seconds:g} s ...", flush=True)
            rows.append(measure(protocol, rate, args.seconds, args.warmup))
    header = (
        "| protocol | target [Hz] | loop [Hz] | delivered [Hz] | jitter p50 [us] | "
        "p99 [us] | max [us] | overruns | missed replies |"
    )
    lines = [header, "|" + "---|" * 9]
    for r in rows:
        lines.append(
            f"| {r['protocol']} | {r['rate_hz']:g} | {r['loop_rate_hz']:.1f} | "
            f"{r['delivered_hz']:.1f} | {r['jitter_p50_us']:.0f} | {r['jitter_p99_us']:.0f} | "
            f"{r['jitter_max_us']:.0f} | {r['overruns']} | {r['missed_replies']} |"
        )
    multi = motors_table(args) if args.motors else []
    if multi:
        lines += [
            "",
            "| motors (MIT) | buses | rate [Hz] | loop [Hz] | delivered [Hz] | jitter p50 / p99 / "
            "max [us] | loop CPU per cycle p50 / p99 [us] | overruns | missed replies | "
            "motors in FAULT |",
            "|" + "---|" * 10,
        ]
        for r in multi:
            lines.append(
                f"| {r['motors']} | {r['buses']} | {r['rate_hz']:g} | {r['loop_rate_hz']:.1f} | "
                f"{r['delivered_hz']:.1f} | {r['jitter_p50_us']:.0f} / {r['jitter_p99_us']:.0f} / "
                f"{r['jitter_max_us']:.0f} | {r['cycle_cpu_p50_us']:.0f} / "
                f"{r['cycle_cpu_p99_us']:.0f} | {r['overruns']} | {r['missed_replies']} | "
                f"{r['faulted_motors']} |"
            )
    rows += multi
    table = "\n".join(lines)
    print(table)
    RESULTS.mkdir(parents=True, exist_ok=True)
    meta = {
        "command": "make bench",
        "seconds": args.seconds,
        "python": sys.version.split()[0],
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "date": time.strftime("%Y-%m-%d"),
    }
    (RESULTS / "driver_loop.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    (RESULTS / "driver_loop.md").write_text(table + "\n")
    return 0 if all(r["exit_code"] == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
