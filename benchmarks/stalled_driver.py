"""The feel-cage cell through the real nodes while the driver's process is stopped now and then.

A host that stalls between computing a command and sending it hands the device a stale
setpoint; a moteus ramps on from the setpoint it receives, so a sweeping arm is pulled back and
the sweep error e_s (the estimator's threshold is e_s + epsilon) comes out too high. This stops
the ``actuator_driver`` process (SIGSTOP, then SIGCONT) for ``--stop-ms`` every ``--every-s``
while one cell runs (`feelcage_run.run_cell`, as `transparency feelcage` runs it), ``--runs``
times, and reports per run e_s against the core engine's (the test holds it to epsilon / 2),
the outcome, t_feel, and the nodes' warnings. Every ROS process runs on loopback with a domain
ID of its own. Results: benchmarks/results/stalled_driver.{md,json}.

    .venv/bin/python benchmarks/stalled_driver.py [--runs 4] [--stop-ms 40] [--every-s 0.7]
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))
import contextlib

from _results import write_results

from transparency_ros.analysis import feelcage_sim as sim
from transparency_ros.core.config import get_actuator
from transparency_ros.ros.feelcage_run import run_cell

RESULTS = Path(__file__).parent / "results"


def _children_named(name: str) -> list[int]:
    """This process's children whose command line runs ``name``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        parent = int(stat.rsplit(")", 1)[1].split()[1])
        if parent == os.getpid() and f"/{name} " in cmdline:
            found.append(int(entry.name))
    return found


class Stopper:
    """Stops the named child process for ``stop_s`` every ``every_s`` (always continued)."""

    def __init__(self, name: str, stop_s: float, every_s: float) -> None:
        self.name, self.stop_s, self.every_s = name, stop_s, every_s
        self.stops = 0
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> Stopper:
        self._thread.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._done.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._done.wait(self.every_s):
            for pid in _children_named(self.name):
                try:
                    os.kill(pid, signal.SIGSTOP)
                    time.sleep(self.stop_s)
                except OSError:
                    continue
                finally:
                    with contextlib.suppress(OSError):
                        os.kill(pid, signal.SIGCONT)
                self.stops += 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--stop-ms", type=float, default=40.0)
    parser.add_argument("--every-s", type=float, default=0.7)
    parser.add_argument("--actuator", default="U10DD")
    parser.add_argument("--ball", default="rubber")
    parser.add_argument("--out", default=str(RESULTS))
    args = parser.parse_args()
    if args.runs < 1 or args.stop_ms <= 0 or args.every_s <= 0:
        parser.error("--runs, --stop-ms and --every-s must be positive")
    setup = sim.load_setup()
    sweep = sim.steady_sweep(get_actuator(args.actuator), setup)
    runs: list[dict[str, Any]] = []
    for i in range(args.runs):
        print(f"[{i + 1}/{args.runs}] {args.ball} / {args.actuator} ...", file=sys.stderr)
        with Stopper("actuator_driver", args.stop_ms * 1e-3, args.every_s) as stopper:
            cell = run_cell(args.actuator, args.ball, setup, settle_s=3.0)
        runs.append({
            "e_s_rad": cell.steady_error_rad, "outcome": cell.record.outcome.value,
            "t_feel_s": cell.record.t_feel_s, "stops": stopper.stops,
            "node_warnings": list(cell.node_warnings),
        })  # fmt: skip
    worst = max(abs(r["e_s_rad"] - sweep.steady_error_rad) for r in runs)
    lines = [
        f"# The {args.ball} / {args.actuator} cell with the driver stopped {args.stop_ms:g} ms "
        f"every {args.every_s:g} s",
        "",
        f"{platform.node()}, {os.cpu_count()} CPUs; core engine e_s "
        f"{sweep.steady_error_rad:.4f} rad, epsilon {setup.epsilon_rad:g} rad",
        "",
        "| run | stops | e_s [rad] | e_s - core [mrad] | outcome | t_feel [ms] | warnings |",
        "|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(runs, 1):
        t_feel = "-" if r["t_feel_s"] is None else f"{r['t_feel_s'] * 1e3:.1f}"
        lines.append(
            f"| {i} | {r['stops']} | {r['e_s_rad']:.4f} | "
            f"{(r['e_s_rad'] - sweep.steady_error_rad) * 1e3:+.1f} | {r['outcome']} | "
            f"{t_feel} | {len(r['node_warnings'])} |"
        )
    lines += ["", f"largest |e_s - core|: {worst * 1e3:.1f} mrad (the test allows "
              f"{setup.epsilon_rad / 2 * 1e3:.1f})"]  # fmt: skip
    write_results(args.out, "stalled_driver", lines, {
        "actuator": args.actuator, "ball": args.ball, "stop_ms": args.stop_ms,
        "every_s": args.every_s, "core_e_s_rad": sweep.steady_error_rad,
        "epsilon_rad": setup.epsilon_rad, "runs": runs,
    })  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
