"""Driver loop benchmark: achieved rate and cycle jitter of `actuator_driver` on the virtual bus.

Each case starts the real executable as its own process (what `ros2 run` does) with the
simulated actuator, lets it warm up, then measures for --seconds:
* the loop's own figures, read from its /diagnostics (rate, jitter p50/p99/max over the last
  5000 cycles; overruns and missed replies counted within the window);
* /joint_states messages delivered to a subscriber in this process (drops show here).
Every process runs on loopback with a domain ID of its own. Results: a table on stdout, JSON and
Markdown in benchmarks/results/.

    .venv/bin/python benchmarks/driver_loop.py [--rates 1000 2000] [--seconds 10]
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

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from transparency_ros.ros.harness import Listener, start_node, stop_node

RESULTS = Path(__file__).parent / "results"


def measure(protocol: str, rate_hz: float, seconds: float, warmup_s: float) -> dict[str, Any]:
    proc = start_node(
        "actuator_driver",
        {"protocol": protocol, "publish_rate_hz": rate_hz, "command_timeout_s": 60.0},
        extra=["--log-level", "warn"],
        quiet=True,
    )
    received = [0]
    diagnostics: list[dict[str, str]] = []
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
                lambda m: diagnostics.extend(
                    {kv.key: kv.value for kv in s.values} for s in m.status
                ),
                10,
            )
            deadline = time.monotonic() + 20.0
            while received[0] == 0 and time.monotonic() < deadline:
                time.sleep(0.05)
            if received[0] == 0:
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
        "rate_hz": rate_hz,
        "loop_rate_hz": float(last["loop_rate_hz"]),
        "delivered_hz": delivered,
        "jitter_p50_us": float(last["jitter_p50_us"]),
        "jitter_p99_us": float(last["jitter_p99_us"]),
        "jitter_max_us": float(last["jitter_max_us"]),
        # counted within the measurement window (diagnostics at its start and end)
        "overruns": int(last["overruns"]) - int(first["overruns"]),
        "missed_replies": int(last["missed_replies_total"]) - int(first["missed_replies_total"]),
        "exit_code": proc.returncode,
    }


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--rates", type=float, nargs="+", default=[1000.0, 2000.0])
    parser.add_argument("--protocols", nargs="+", default=["mit", "odrive", "moteus"])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--warmup", type=float, default=2.0)
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
