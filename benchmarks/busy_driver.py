"""The driver on a busy computer: `actuator_driver` beside CPU hogs, for minutes, with its defaults.

Robot computers are busy. Each case starts the real executable (1 simulated motor, or the
README's three-motor example) with its default parameters (reply watchdog: `reply_silence_s`
0.1 s), starts ``--hogs`` processes that each spin one core, and listens for ``--seconds``:

* whether any motor faulted (the goal: none), and the driver's own figures from /diagnostics:
  the longest silence of a motor that then answered, how late cycles started (p99, max: the
  host's stalls as the loop saw them), the garbage collector's pauses (count, longest), replies
  late and missed;
* the stall histogram: the gaps between consecutive /joint_states stamps (the stamps are when
  the replies were on the bus, so a gap is time the loop did not sample), binned below 1.5 ms
  (on time), 1.5-2 ms, 2-5, 5-10, 10-20, 20-50, 50-100, 100-200, 200-500 ms and above.

Every ROS process runs on loopback with a domain ID of its own. Results: benchmarks/results/
busy_driver.{md,json}.

    .venv/bin/python benchmarks/busy_driver.py [--seconds 600] [--hogs 2] [--motors 1 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_results

from transparency_ros.ros.harness import Listener, start_node, stop_node

RESULTS = Path(__file__).parent / "results"
EDGES_MS = [1.5, 2, 5, 10, 20, 50, 100, 200, 500]  # below 1.5 ms: on time at 1 kHz
HOG = "import time\nend = time.monotonic() + {s}\nwhile time.monotonic() < end: pass\n"


def start_hogs(count: int, seconds: float) -> list[subprocess.Popen[bytes]]:
    return [subprocess.Popen([sys.executable, "-c", HOG.format(s=seconds)]) for _ in range(count)]


def stall_histogram(stamps_ns: np.ndarray) -> dict[str, int]:
    gaps_ms = np.diff(np.sort(stamps_ns)) * 1e-6
    counts = {"< 1.5 ms": int((gaps_ms < EDGES_MS[0]).sum())}
    for low, high in zip(EDGES_MS, [*EDGES_MS[1:], None], strict=True):
        inside = gaps_ms >= low if high is None else (gaps_ms >= low) & (gaps_ms < high)
        counts[f"{low}-{high} ms" if high else f">= {low} ms"] = int(inside.sum())
    return counts


def measure(motors: int, seconds: float, hogs: int) -> dict[str, Any]:
    params: dict[str, Any] = {}
    if motors > 1:
        params = {"motor_ids": list(range(1, motors + 1)),
                  "joint_names": ["hip", "knee", "ankle", "j4", "j5", "j6"][:motors]}  # fmt: skip
    proc = start_node("actuator_driver", params, extra=["--log-level", "warn"], quiet=True)
    stamps: list[int] = []
    diagnostics: list[dict[str, Any]] = []
    errors: list[str] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        values: dict[str, Any] = {}
        for status in msg.status:
            values.update({kv.key: kv.value for kv in status.values})
            if status.level == DiagnosticStatus.ERROR:
                errors.append(f"{status.name}: {status.message}")
        values["longest_silence_ms"] = max(
            float(kv.value) for s in msg.status for kv in s.values
            if kv.key == "longest_silence_ms"
        )  # fmt: skip
        diagnostics.append(values)

    hog_procs: list[subprocess.Popen[bytes]] = []
    try:
        with Listener(f"busy_driver_bench_{motors}") as node:
            node.create_subscription(
                JointState, "/joint_states",
                lambda m: stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec),
                1000,
            )  # fmt: skip
            node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
            deadline = time.monotonic() + 20.0
            while not stamps and time.monotonic() < deadline:
                time.sleep(0.05)
            if not stamps:
                raise RuntimeError(f"{motors} motor(s): no /joint_states within 20 s")
            hog_procs = start_hogs(hogs, seconds + 5.0)
            start, first = time.monotonic(), len(stamps)
            next_report = start + 60.0
            while time.monotonic() - start < seconds and proc.poll() is None:
                time.sleep(0.5)
                if time.monotonic() >= next_report:
                    next_report += 60.0
                    print(f"  {time.monotonic() - start:4.0f} s: {len(stamps) - first} samples, "
                          f"faults: {len(errors)}", flush=True)  # fmt: skip
            elapsed = time.monotonic() - start
            window = np.array(stamps[first:], dtype=np.int64)
            time.sleep(1.2)  # the diagnostics covering the end
            last = diagnostics[-1]
    finally:
        for hog in hog_procs:
            hog.kill()
            hog.wait()
        stop_node(proc)
    return {
        "motors": motors, "hogs": hogs, "seconds": round(elapsed, 1),
        "faults": sorted(set(errors)), "samples": int(window.size),
        "sample_rate_hz": round(window.size / elapsed, 1),
        "stall_histogram": stall_histogram(window),
        "largest_gap_ms": round(float(np.diff(np.sort(window)).max()) * 1e-6, 1),
        "longest_silence_ms": last["longest_silence_ms"],
        "cycle_late_p99_us": float(last["cycle_late_p99_us"]),
        "cycle_late_max_ms": float(last["cycle_late_max_ms"]),
        "gc_collections": int(last["gc_collections"]),
        "gc_full_collections": int(last["gc_full_collections"]),
        "gc_pause_max_ms": float(last["gc_pause_max_ms"]),
        "missed_replies": sum(int(v) for k, v in last.items() if k == "missed_replies_total"),
        "overruns": int(last["overruns"]),
        "exit_code": proc.returncode,
    }  # fmt: skip


def table(rows: list[dict[str, Any]], command: str) -> list[str]:
    bins = list(rows[0]["stall_histogram"])
    lines = [
        f"# Driver beside CPU hogs ({platform.node()}, {os.cpu_count()} cores)",
        "",
        f"`{command}`, default parameters (reply_silence_s 0.1 s, 1 kHz).",
        "",
        "| motors | hogs | minutes | faults | samples/s | largest gap ms | longest silence ms "
        "| cycle late p99 us / max ms | gc pauses (full) / max ms |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['motors']} | {r['hogs']} | {r['seconds'] / 60:.1f} | "
            f"{'; '.join(r['faults']) or 'none'} | {r['sample_rate_hz']:.1f} | "
            f"{r['largest_gap_ms']:.1f} | {r['longest_silence_ms']} | "
            f"{r['cycle_late_p99_us']:.0f} / {r['cycle_late_max_ms']:.1f} | "
            f"{r['gc_collections']} ({r['gc_full_collections']}) / {r['gc_pause_max_ms']:.2f} |"
        )
    lines += ["", "Gaps between consecutive /joint_states stamps (the stall histogram):", "",
              "| motors | " + " | ".join(bins) + " |", "|---|" + "---|" * len(bins)]  # fmt: skip
    for r in rows:
        lines.append(
            f"| {r['motors']} | " + " | ".join(str(r["stall_histogram"][b]) for b in bins) + " |"
        )
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--hogs", type=int, default=2)
    parser.add_argument("--motors", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--out", default=str(RESULTS))
    args = parser.parse_args()
    rows = []
    for motors in args.motors:
        print(f"{motors} motor(s) beside {args.hogs} hogs for {args.seconds:g} s ...", flush=True)
        rows.append(measure(motors, args.seconds, args.hogs))
    command = "python benchmarks/busy_driver.py " + " ".join(sys.argv[1:])
    write_results(args.out, "busy_driver", table(rows, command.strip()), rows)
    return 1 if any(r["faults"] for r in rows) else 0


if __name__ == "__main__":
    raise SystemExit(main())
