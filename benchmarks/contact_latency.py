"""Contact latency through ROS 2: from a /joint_states publish to the estimator's answers.

    .venv/bin/python benchmarks/contact_latency.py [--rates 1000 10000] [--seconds 60] [--out DIR]

A source thread in this process publishes /joint_states at the rate (it sleeps until each
period's start, stamps header.stamp with the wall clock and publishes at once) with a
deflection of 0.2 rad for 5 samples in every 50, so the estimator (contact_onset_rad 0.1,
release 0.05) reports a contact onset every 50 samples.

Two latencies per answer:
* **publish -> publish**, what the issue asks for: the estimator notes, at its publish call
  for /contact (and /estimated_effort), the wall-clock time minus the sample's stamp, in
  a histogram it reports on /diagnostics (``onset_age_*``, ``sample_age_*``; within 1 %). The
  benchmark clears it (``~/reset``) after the start-up probe and reads it after the run.
* **received**: the arrival of /contact at a listener in this process (its own thread,
  serialized bytes), i.e. a second delivery on top. /contact drops: onsets with no /contact at
  the listener. Samples unanswered: /joint_states messages sent minus the estimates the
  estimator published. Nobody subscribes /estimated_effort: a subscriber in another process
  makes each publish a delivery, about 0.1 ms of the estimator's time per sample here.

Two set-ups:
* **cross-process**: `contact_estimator` runs as its own process (what `ros2 run` does);
* **one process**: the estimator node is composed into this process (on the listener's
  SingleThreadedExecutor) with ``in_process:=true``: the source hands it each sample directly,
  as the driver does (``ros.in_process``), and publishes it through DDS as well.

``--priority N`` runs the estimator's and the listener's hot-path threads at SCHED_FIFO N.

Every ROS process runs on loopback with a domain ID of its own. Writes
benchmarks/results/contact_latency.md and .json.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from _results import write_results

from transparency_ros.core.cdr import encode_joint_state, header_stamp_ns, write_header_stamp

PERIOD_SAMPLES = 50  # an onset every 50 samples
DEFLECTED_SAMPLES = 5
ESTIMATOR_PARAMS = {"contact_onset_rad": 0.1, "contact_release_rad": 0.05, "k_s": 2.0}


class Recorder:
    """Arrival times of the estimator's outputs, by the stamp of the sample they answer; the
    outputs are taken as bytes on a hot path of the listener (its own thread), so the listener
    adds no executor time to what it measures."""

    def __init__(self) -> None:
        self.contact: dict[int, int] = {}
        self.estimator: dict[str, str] = {}  # its last /diagnostics values
        self.estimator_stamp_ns = 0
        self.periods: list[dict[str, str]] = []  # every /diagnostics of the estimator

    def on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.startswith("contact_estimator"):
                self.estimator = {kv.key: kv.value for kv in status.values}
                self.periods.append(self.estimator)
                self.estimator_stamp_ns = _ns(msg.header.stamp)

    def on_contact(self, data: bytes) -> None:
        self.contact[header_stamp_ns(data)] = time.time_ns()


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class Source:
    """/joint_states at ``rate_hz`` from a thread: waits for each period's start (sleeping, so
    the GIL is free), then stamps with the wall clock and publishes at once: the message is
    serialized beforehand and only its stamp written in, so the stamp is the publish call's
    time, as the estimator's is. A deflection of 0.2 rad for 5 samples in every 50."""

    def __init__(self, publish: Any) -> None:
        self.publish = publish
        self.sent: list[int] = []
        self.templates = [
            bytearray(encode_joint_state(0, 0, "", ["joint"], position=[p], velocity=[0.0]))
            for p in (0.0, 0.2)
        ]

    def run(self, rate_hz: float, seconds: float) -> None:
        period = 1.0 / rate_hz
        start = time.perf_counter() + 0.2
        for i in range(int(seconds * rate_hz)):
            delay = start + i * period - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            message = self.templates[i % PERIOD_SAMPLES < DEFLECTED_SAMPLES]
            t_ns = time.time_ns()
            write_header_stamp(message, t_ns // 1_000_000_000, t_ns % 1_000_000_000)
            self.publish(bytes(message))
            self.sent.append(t_ns)


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


def _hist(values: dict[str, str], key: str) -> dict[str, float]:
    """The estimator's own publish-time statistics from its /diagnostics."""
    return {
        "count": float(values.get(f"{key}_count", "nan")),
        "median_ms": float(values.get(f"{key}_p50_us", "nan")) / 1e3,
        "p99_ms": float(values.get(f"{key}_p99_us", "nan")) / 1e3,
        "max_ms": float(values.get(f"{key}_max_us", "nan")) / 1e3,
    }


def _handler_time(periods: list[dict[str, str]]) -> dict[str, float]:
    def values(key: str) -> np.ndarray:
        v = np.array([float(p.get(key, "nan")) for p in periods])
        return v[np.isfinite(v)] if v.size else v

    p50, p99, top = (values(f"latency_{k}_us") for k in ("p50", "p99", "max"))
    return {
        "p50": float(np.median(p50)) if p50.size else float("nan"),
        "p99": float(p99.max()) if p99.size else float("nan"),
        "max": float(top.max()) if top.size else float("nan"),
    }


def measure(setup: str, rate_hz: float, seconds: float, priority: int = 0) -> dict[str, Any]:
    import rclpy  # noqa: PLC0415
    from diagnostic_msgs.msg import DiagnosticArray  # noqa: PLC0415
    from geometry_msgs.msg import WrenchStamped  # noqa: PLC0415
    from rclpy.context import Context  # noqa: PLC0415
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.node import Node  # noqa: PLC0415
    from rclpy.parameter import Parameter  # noqa: PLC0415
    from sensor_msgs.msg import JointState  # noqa: PLC0415
    from std_srvs.srv import Trigger  # noqa: PLC0415

    from transparency_ros.ros import in_process  # noqa: PLC0415
    from transparency_ros.ros.harness import start_node, stop_node  # noqa: PLC0415
    from transparency_ros.ros.hot_path import HotPath  # noqa: PLC0415
    from transparency_ros.ros.services import ServiceCaller  # noqa: PLC0415
    from transparency_ros.rosenv import local_ros_env  # noqa: PLC0415

    proc = None
    if setup == "cross-process":
        proc = start_node(
            "contact_estimator",
            {**ESTIMATOR_PARAMS, "hot_path_priority": priority},
            extra=["--log-level", "warn"],
            quiet=True,
        )
    else:
        import os  # noqa: PLC0415

        env = local_ros_env()
        os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    context = Context()
    rclpy.init(context=context)
    rec = Recorder()
    executor = SingleThreadedExecutor(context=context)
    nodes = []
    try:
        listener = Node("latency_listener", context=context)
        nodes.append(listener)
        hot = HotPath(listener, priority=priority)
        hot.subscribe(WrenchStamped, "/contact", 1000, rec.on_contact)
        hot.start()
        listener.create_subscription(DiagnosticArray, "/diagnostics", rec.on_diagnostics, 10)
        if setup == "one process":
            from transparency_ros.ros.contact_estimator import (  # noqa: PLC0415
                ContactEstimatorNode,
            )

            estimator = ContactEstimatorNode(
                context=context,
                parameter_overrides=[
                    Parameter(k, value=v)
                    for k, v in {
                        **ESTIMATOR_PARAMS,
                        "in_process": True,
                        "hot_path_priority": priority,
                    }.items()
                ],
            )
            nodes.append(estimator)
        source_node = Node("latency_source", context=context)
        nodes.append(source_node)
        pub = source_node.create_publisher(JointState, "/joint_states", 1000)
        # composed: the estimator takes the samples in-process (ros.in_process), as with the driver
        source = Source(partial(in_process.publish, pub, context, "/joint_states"))
        for node in nodes:
            executor.add_node(node)
        spin = threading.Thread(target=executor.spin, daemon=True)
        spin.start()
        # wait until the estimator answers, then clear its statistics of these probe samples
        deadline = time.monotonic() + 20.0
        while not rec.contact and time.monotonic() < deadline:
            Source(source.publish).run(100.0, 0.05)
        if not rec.contact:
            raise RuntimeError(f"{setup}: the estimator does not answer /joint_states")
        ServiceCaller(listener)(Trigger, "/contact_estimator/reset", Trigger.Request())
        time.sleep(0.3)
        rec.contact.clear()
        rec.periods.clear()
        source.run(rate_hz, seconds)
        # the last answers, then a diagnostics message published after them
        settled_ns = time.time_ns() + 500_000_000
        deadline = time.monotonic() + 10.0
        while rec.estimator_stamp_ns < settled_ns and time.monotonic() < deadline:
            time.sleep(0.05)
        estimator_values = dict(rec.estimator)
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        if proc is not None:
            stop_node(proc)
    sent = source.sent
    achieved = (len(sent) - 1) / ((sent[-1] - sent[0]) / 1e9) if len(sent) > 1 else 0.0
    onsets = [s for i, s in enumerate(sent) if i % PERIOD_SAMPLES == 0]
    return {
        "setup": setup,
        "rate_hz": rate_hz,
        "seconds": seconds,
        "published_hz": achieved,
        "sent": len(sent),
        # /contact received by the listener (another process, or this one): two deliveries
        "contacts": _stats(onsets, rec.contact),
        # the estimator's own clock at its publish: /joint_states publish -> its publish
        "sample_publish": _hist(estimator_values, "sample_age"),
        "contact_publish": _hist(estimator_values, "onset_age"),
        # samples the estimator never answered (its count of estimates since the reset)
        "sample_drops": len(sent) - int(_hist(estimator_values, "sample_age")["count"]),
        # the estimator's own time in its /joint_states handler: per diagnostics period (1 s),
        # the median period's p50, the worst period's p99 and max
        "callback_us": _handler_time(rec.periods),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[1000.0, 10000.0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--setups", nargs="+", default=["cross-process", "one process"])
    parser.add_argument(
        "--priority",
        type=int,
        default=0,
        help="SCHED_FIFO priority of the estimator's and the listener's hot-path threads "
        "(the estimator's hot_path_priority; default 0: normal scheduling)",
    )
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    parser.add_argument("--name", default="contact_latency", help="results file name")
    args = parser.parse_args()
    # the source thread and the executor share this interpreter: hand the GIL over quickly
    sys.setswitchinterval(5e-5)
    rows = []
    for setup in args.setups:
        for rate in args.rates:
            print(f"{setup}, {rate:g} Hz for {args.seconds:g} s ...", flush=True)
            row = measure(setup, rate, args.seconds, args.priority)
            row["priority"] = args.priority
            rows.append(row)
            c, cp, sp = row["contacts"], row["contact_publish"], row["sample_publish"]
            print(
                f"  published {row['published_hz']:.0f} Hz; /contact: drops {c['drops']}/"
                f"{c['expected']}, publish->publish median {cp['median_ms']:.3f} ms, p99 "
                f"{cp['p99_ms']:.3f}, max {cp['max_ms']:.2f}; received median "
                f"{c['median_ms']:.3f}, p99 {c['p99_ms']:.3f}; samples unanswered "
                f"{row['sample_drops']}, publish->publish median {sp['median_ms']:.3f}, p99 "
                f"{sp['p99_ms']:.3f}",
                flush=True,
            )
    lines = [
        f"Contact latency through ROS 2, {args.seconds:g} s per case"
        + (f", hot-path threads at SCHED_FIFO {args.priority}" if args.priority else "")
        + ". publish -> publish: from "
        "the /joint_states publish to the estimator's publish of the answer, on the "
        "estimator's clock (its /diagnostics, within 1 %); received: to the arrival of /contact "
        "at a listener in the source's process (a second delivery). /contact drops: onsets "
        "whose /contact never reached the listener; samples unanswered: /joint_states "
        "messages the estimator never answered.",
        "",
        "| set-up | rate [Hz] | published [Hz] | /contact drops | /contact publish -> publish "
        "median / p99 / max [ms] | /contact received median / p99 / max [ms] "
        "| samples unanswered | /estimated_effort publish -> publish median / p99 / max [ms] "
        "| estimator handler p50 / p99 / max [us] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        c, cb = r["contacts"], r["callback_us"]
        cp, sp = r["contact_publish"], r["sample_publish"]
        lines.append(
            f"| {r['setup']} | {r['rate_hz']:g} | {r['published_hz']:.0f} "
            f"| {c['drops']}/{c['expected']} "
            f"| {cp['median_ms']:.3f} / {cp['p99_ms']:.3f} / {cp['max_ms']:.2f} "
            f"| {c['median_ms']:.3f} / {c['p99_ms']:.3f} / {c['max_ms']:.2f} "
            f"| {r['sample_drops']}/{r['sent']} "
            f"| {sp['median_ms']:.3f} / {sp['p99_ms']:.3f} / {sp['max_ms']:.2f} "
            f"| {cb['p50']:.0f} / {cb['p99']:.0f} / {cb['max']:.0f} |"
        )
    command = " ".join(["benchmarks/contact_latency.py", *sys.argv[1:]])
    lines += ["", f"(`.venv/bin/python {command}`)"]
    write_results(args.out, args.name, lines, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
