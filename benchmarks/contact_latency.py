"""Contact latency through ROS 2: from a /joint_states publish to the matching outputs.

    .venv/bin/python benchmarks/contact_latency.py [--rates 1000 10000] [--seconds 60] [--out DIR]

A source in this process publishes /joint_states at the rate (a thread that waits for each
period's start, then publishes; header.stamp = the wall-clock time of the publish) with a
deflection of 0.2 rad for 5 samples in every 50, so the estimator (contact_onset_rad 0.1,
release 0.05) reports a contact onset every 50 samples. A listener in this process records the
arrival time of every /estimated_effort (one per sample) and /contact (one per onset) message;
latency = arrival - stamp of the sample it answers, i.e. publish -> estimator -> publish ->
listener (an upper bound of publish-to-publish, two deliveries instead of one). Drops: samples
with no /estimated_effort, onsets with no /contact.

Two set-ups:
* **cross-process**: `contact_estimator` runs as its own process (what `ros2 run` does);
* **one process**: the estimator node is composed into this process, on the executor the
  listener uses (rclpy's SingleThreadedExecutor; the source publishes from its own thread).

Every ROS process runs on loopback with a domain ID of its own. Writes
benchmarks/results/contact_latency.md and .json.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from _results import write_results

PERIOD_SAMPLES = 50  # an onset every 50 samples
DEFLECTED_SAMPLES = 5
ESTIMATOR_PARAMS = {"contact_onset_rad": 0.1, "contact_release_rad": 0.05, "k_s": 2.0}


class Recorder:
    """Arrival times of the estimator's outputs, by the stamp of the sample they answer."""

    def __init__(self) -> None:
        self.effort: dict[int, int] = {}
        self.contact: dict[int, int] = {}
        self.estimator: dict[str, str] = {}  # its last /diagnostics values

    def on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.startswith("contact_estimator"):
                self.estimator = {kv.key: kv.value for kv in status.values}

    @staticmethod
    def _ns(msg: Any) -> int:
        return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)

    def on_effort(self, msg: Any) -> None:
        self.effort[self._ns(msg)] = time.time_ns()

    def on_contact(self, msg: Any) -> None:
        self.contact[self._ns(msg)] = time.time_ns()


def _source(
    pub: Any, rate_hz: float, seconds: float, sent: list[int], stop: threading.Event | None
) -> None:
    """Publish for ``seconds``; with ``stop`` None: no deflection (a probe)."""
    from builtin_interfaces.msg import Time  # noqa: PLC0415
    from sensor_msgs.msg import JointState  # noqa: PLC0415

    period = 1.0 / rate_hz
    start = time.perf_counter() + 0.5
    n = int(seconds * rate_hz)
    for i in range(n):
        target = start + i * period
        # sleep, not spin: a spinning thread holds the GIL the listener's executor needs
        delay = target - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        if stop is not None and stop.is_set():
            break
        msg = JointState()
        t_ns = time.time_ns()
        msg.header.stamp = Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
        msg.name = ["joint"]
        deflected = stop is not None and i % PERIOD_SAMPLES < DEFLECTED_SAMPLES
        msg.position = [0.2 if deflected else 0.0]
        msg.velocity = [0.0]
        pub.publish(msg)
        sent.append(t_ns)


def _stats(sent: list[int], arrivals: dict[int, int]) -> dict[str, float]:
    """Each sent stamp matched with the arrival whose stamp is within 1 us of it (the estimator
    carries stamps as float seconds: the nanoseconds come back rounded)."""
    stamps = np.array(sent, dtype=np.int64)
    keys = np.array(sorted(arrivals), dtype=np.int64)
    got = np.full(stamps.size, -1, dtype=np.int64)
    if keys.size:
        j = np.clip(np.searchsorted(keys, stamps), 1, keys.size - 1)
        nearest = np.where(
            np.abs(keys[j - 1] - stamps) <= np.abs(keys[j] - stamps), keys[j - 1], keys[j]
        )
        close = np.abs(nearest - stamps) <= 1_000
        got[close] = [arrivals[int(k)] for k in nearest[close]]
    ok = got >= 0
    lat = (got[ok] - stamps[ok]) / 1e6  # ms
    return {
        "expected": int(stamps.size),
        "received": int(ok.sum()),
        "drops": int((~ok).sum()),
        "median_ms": float(np.median(lat)) if lat.size else float("nan"),
        "p99_ms": float(np.percentile(lat, 99)) if lat.size else float("nan"),
        "max_ms": float(lat.max()) if lat.size else float("nan"),
    }


def measure(setup: str, rate_hz: float, seconds: float) -> dict[str, Any]:
    import rclpy  # noqa: PLC0415
    from diagnostic_msgs.msg import DiagnosticArray  # noqa: PLC0415
    from geometry_msgs.msg import WrenchStamped  # noqa: PLC0415
    from rclpy.context import Context  # noqa: PLC0415
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.node import Node  # noqa: PLC0415
    from rclpy.parameter import Parameter  # noqa: PLC0415
    from sensor_msgs.msg import JointState  # noqa: PLC0415

    from transparency_ros.ros.harness import start_node, stop_node  # noqa: PLC0415
    from transparency_ros.rosenv import local_ros_env  # noqa: PLC0415

    proc = None
    if setup == "cross-process":
        proc = start_node(
            "contact_estimator", ESTIMATOR_PARAMS, extra=["--log-level", "warn"], quiet=True
        )
    else:
        import os  # noqa: PLC0415

        env = local_ros_env()
        os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    context = Context()
    rclpy.init(context=context)
    rec = Recorder()
    sent: list[int] = []
    stop = threading.Event()
    executor = SingleThreadedExecutor(context=context)
    nodes = []
    try:
        listener = Node("latency_listener", context=context)
        listener.create_subscription(JointState, "/estimated_effort", rec.on_effort, 1000)
        listener.create_subscription(WrenchStamped, "/contact", rec.on_contact, 1000)
        listener.create_subscription(DiagnosticArray, "/diagnostics", rec.on_diagnostics, 10)
        nodes.append(listener)
        if setup == "one process":
            from transparency_ros.ros.contact_estimator import (  # noqa: PLC0415
                ContactEstimatorNode,
            )

            estimator = ContactEstimatorNode(
                context=context,
                parameter_overrides=[Parameter(k, value=v) for k, v in ESTIMATOR_PARAMS.items()],
            )
            nodes.append(estimator)
        source = Node("latency_source", context=context)
        nodes.append(source)
        pub = source.create_publisher(JointState, "/joint_states", 1000)
        for node in nodes:
            executor.add_node(node)
        spin = threading.Thread(target=executor.spin, daemon=True)
        spin.start()
        # wait until the estimator answers
        probe: list[int] = []
        deadline = time.monotonic() + 20.0
        while not rec.effort and time.monotonic() < deadline:
            _source(pub, 100.0, 0.05, probe, None)
        if not rec.effort:
            raise RuntimeError(f"{setup}: the estimator does not answer /joint_states")
        time.sleep(0.5)
        rec.effort.clear()
        rec.contact.clear()
        _source(pub, rate_hz, seconds, sent, stop)
        time.sleep(1.2)  # the last answers, and a diagnostics period
    finally:
        stop.set()
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        if proc is not None:
            stop_node(proc)
    achieved = (len(sent) - 1) / ((sent[-1] - sent[0]) / 1e9) if len(sent) > 1 else 0.0
    onsets = [s for i, s in enumerate(sent) if i % PERIOD_SAMPLES == 0]
    return {
        "setup": setup,
        "rate_hz": rate_hz,
        "seconds": seconds,
        "published_hz": achieved,
        "samples": _stats(sent, rec.effort),
        "contacts": _stats(onsets, rec.contact),
        # the estimator's own time in its /joint_states callback, last 5000 samples
        "callback_us": {
            k: float(rec.estimator.get(f"latency_{k}_us", "nan")) for k in ("p50", "p99", "max")
        },
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[1000.0, 10000.0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--setups", nargs="+", default=["cross-process", "one process"])
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    # the source thread and the executor share this interpreter: hand the GIL over quickly
    sys.setswitchinterval(5e-5)
    rows = []
    for setup in args.setups:
        for rate in args.rates:
            print(f"{setup}, {rate:g} Hz for {args.seconds:g} s ...", flush=True)
            row = measure(setup, rate, args.seconds)
            rows.append(row)
            s, c = row["samples"], row["contacts"]
            print(
                f"  published {row['published_hz']:.0f} Hz; /estimated_effort drops "
                f"{s['drops']}/{s['expected']}, median {s['median_ms']:.3f} ms, p99 "
                f"{s['p99_ms']:.3f}, max {s['max_ms']:.2f}; /contact drops {c['drops']}/"
                f"{c['expected']}, median {c['median_ms']:.3f} ms, p99 {c['p99_ms']:.3f}",
                flush=True,
            )
    lines = [
        "Contact latency: /joint_states publish -> /contact (and /estimated_effort) received "
        f"in the publishing process, {args.seconds:g} s per case",
        "",
        "| set-up | rate [Hz] | published [Hz] | /contact drops | /contact median [ms] "
        "| p99 [ms] | max [ms] | samples dropped (/estimated_effort) | sample median [ms] "
        "| p99 [ms] | estimator callback p50 / p99 / max [us] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        s, c, cb = r["samples"], r["contacts"], r["callback_us"]
        lines.append(
            f"| {r['setup']} | {r['rate_hz']:g} | {r['published_hz']:.0f} "
            f"| {c['drops']}/{c['expected']} | {c['median_ms']:.3f} | {c['p99_ms']:.3f} "
            f"| {c['max_ms']:.2f} | {s['drops']}/{s['expected']} | {s['median_ms']:.3f} "
            f"| {s['p99_ms']:.3f} | {cb['p50']:.0f} / {cb['p99']:.0f} / {cb['max']:.0f} |"
        )
    lines += ["", "(`.venv/bin/python benchmarks/contact_latency.py`)"]
    write_results(args.out, "contact_latency", lines, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
