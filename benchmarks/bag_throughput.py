"""Bag evaluation throughput: JointState / WrenchStamped / PointStamped from MCAP into numpy.

    .venv/bin/python benchmarks/bag_throughput.py [--messages 600000] [--big 10000000] [--out DIR]

A rosbag2 MCAP bag (zstd chunks, as `transparency rig` writes) holds ``--messages`` messages,
a third of each type, with values that change from message to message. Three readers turn every
numeric field the evaluation uses (stamps, position / velocity / effort, force, point) into
numpy arrays:
* this project's fast path (``transparency_ros.bag.fast.read_fields``);
* rosbags: ``Reader.messages`` + ``typestore.deserialize_cdr`` per message;
* mcap-ros2-support: ``McapReader.iter_decoded_messages`` with its ``DecoderFactory``.
The arrays of all three are compared value for value. Then the peak resident memory of the fast
path reading a ``--big``-message bag (in a fresh process; the bag is written once into
benchmarks/.cache/ and reused). Writes benchmarks/results/bag_throughput.md and .json.
"""

from __future__ import annotations

import argparse
import multiprocessing
import resource
import time
from pathlib import Path
from typing import Any

import numpy as np
from _results import write_results

CACHE = Path(__file__).parent / ".cache"
TOPICS = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/load_cell": "geometry_msgs/msg/WrenchStamped",
    "/shuttle/height": "geometry_msgs/msg/PointStamped",
}
FIELDS = {  # what the evaluation reads, per topic
    "/joint_states": ["position[0]", "velocity[0]", "effort[0]"],
    "/load_cell": ["wrench.force.z"],
    "/shuttle/height": ["point.z"],
}


def _templates() -> dict[str, bytes]:
    from transparency_ros.bag.writer import TYPESTORE, message_types, time_msg  # noqa: PLC0415

    types = message_types()
    header = types["std_msgs/msg/Header"](stamp=time_msg(0), frame_id="rig")
    one = np.array([0.0])
    vec = types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    msgs = {
        "/joint_states": types["sensor_msgs/msg/JointState"](
            header=header, name=["joint"], position=one, velocity=one, effort=one
        ),
        "/load_cell": types["geometry_msgs/msg/WrenchStamped"](
            header=header, wrench=types["geometry_msgs/msg/Wrench"](force=vec, torque=vec)
        ),
        "/shuttle/height": types["geometry_msgs/msg/PointStamped"](
            header=header, point=types["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0)
        ),
    }
    return {t: bytes(TYPESTORE.serialize_cdr(m, TOPICS[t])) for t, m in msgs.items()}


def write_bag(path: Path, messages: int) -> Path:
    """The bag (cached: written once per size)."""
    from transparency_ros.bag.fast import layout  # noqa: PLC0415
    from transparency_ros.bag.writer import TYPESTORE, BagWriter  # noqa: PLC0415

    if (path / "metadata.yaml").exists():
        return path
    rng = np.random.default_rng(1)
    per = messages // len(TOPICS)
    raw = {}
    for topic, template in _templates().items():
        lay = layout(TYPESTORE, TOPICS[topic], template)
        assert lay is not None
        rows = np.tile(np.frombuffer(template, dtype=np.uint8), (per, 1))
        offsets = {leaf.path: leaf.offset for leaf in lay.leaves}
        t_ns = 1_700_000_000_000_000_000 + np.arange(per, dtype=np.int64) * 1_000_000
        rows[:, offsets["header.stamp.sec"] : offsets["header.stamp.sec"] + 4] = (
            (t_ns // 1_000_000_000).astype("<i4").view(np.uint8).reshape(per, 4)
        )
        rows[:, offsets["header.stamp.nanosec"] : offsets["header.stamp.nanosec"] + 4] = (
            (t_ns % 1_000_000_000).astype("<u4").view(np.uint8).reshape(per, 4)
        )
        for field in FIELDS[topic]:
            rows[:, offsets[field] : offsets[field] + 8] = (
                rng.normal(size=per).astype("<f8").view(np.uint8).reshape(per, 8)
            )
        raw[topic] = (t_ns, rows)
    tmp = path.with_name(path.name + ".writing")
    with BagWriter(tmp) as bag:
        for topic, msgtype in TOPICS.items():
            bag.add(topic, msgtype)
        for i in range(per):
            for topic, (t_ns, rows) in raw.items():
                bag.write(topic, int(t_ns[i]), rows[i].tobytes())
    tmp.rename(path)
    return path


def read_fast(bag_dir: Path) -> dict[str, dict[str, np.ndarray]]:
    from transparency_ros.bag.fast import read_topics  # noqa: PLC0415
    from transparency_ros.bag.reader import normalise_type, open_bag  # noqa: PLC0415

    out = {}
    with open_bag(bag_dir) as bag:
        found = read_topics(bag.storage_paths, list(TOPICS), bag.typestore, normalise_type)
        for topic in TOPICS:
            fields = found[topic]
            assert fields is not None, f"{topic}: the fast path did not apply"
            out[topic] = {
                "sec": fields.fields["header.stamp.sec"],
                "nanosec": fields.fields["header.stamp.nanosec"],
                **{f: fields.fields[f] for f in FIELDS[topic]},
            }
    return out


def _get(msg: Any, path: str) -> Any:
    value = msg
    for part in path.replace("]", "").replace("[", ".").split("."):
        value = value[int(part)] if part.isdigit() else getattr(value, part)
    return value


def _collect(messages: Any) -> dict[str, dict[str, np.ndarray]]:
    rows: dict[str, dict[str, list[Any]]] = {
        t: {k: [] for k in ["sec", "nanosec", *FIELDS[t]]} for t in TOPICS
    }
    for topic, msg in messages:
        r = rows[topic]
        r["sec"].append(msg.header.stamp.sec)
        r["nanosec"].append(msg.header.stamp.nanosec)
        for f in FIELDS[topic]:
            r[f].append(_get(msg, f))
    return {t: {k: np.array(v) for k, v in r.items()} for t, r in rows.items()}


def read_rosbags(bag_dir: Path) -> dict[str, dict[str, np.ndarray]]:
    from rosbags.rosbag2 import Reader  # noqa: PLC0415
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415

    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag_dir) as reader:
        return _collect(
            (c.topic, store.deserialize_cdr(data, c.msgtype)) for c, _t, data in reader.messages()
        )


def read_mcap_ros2(bag_dir: Path) -> dict[str, dict[str, np.ndarray]]:
    from mcap.reader import make_reader  # noqa: PLC0415
    from mcap_ros2.decoder import DecoderFactory  # noqa: PLC0415

    (path,) = sorted(bag_dir.glob("*.mcap"))
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return _collect(
            (channel.topic, msg)
            for _s, channel, _m, msg in reader.iter_decoded_messages(log_time_order=False)
        )


def _same(a: dict[str, dict[str, np.ndarray]], b: dict[str, dict[str, np.ndarray]]) -> bool:
    """Equal value for value (each reader's own order; all three keep the write order here)."""
    return all(
        np.array_equal(np.asarray(a[t][k], dtype=float), np.asarray(b[t][k], dtype=float))
        for t in TOPICS
        for k in a[t]
    )


def _peak(bag_dir: str) -> tuple[float, float, int]:
    started = time.perf_counter()
    arrays = read_fast(Path(bag_dir))
    n = sum(next(iter(v.values())).size for v in arrays.values())
    return (
        time.perf_counter() - started,
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        n,
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=600_000)
    parser.add_argument("--big", type=int, default=10_000_000, help="0: skip the memory run")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    CACHE.mkdir(exist_ok=True)
    started = time.perf_counter()
    bag = write_bag(CACHE / f"throughput_{args.messages}", args.messages)
    print(f"bag of {args.messages} messages ready ({time.perf_counter() - started:.0f} s)")
    results, arrays = {}, {}
    read_fast(bag)  # compile the record index once (cached on disk afterwards)
    for name, fn in (
        ("this project (fast path)", read_fast),
        ("rosbags deserialize", read_rosbags),
        ("mcap-ros2-support", read_mcap_ros2),
    ):
        t0 = time.perf_counter()
        arrays[name] = fn(bag)
        seconds = time.perf_counter() - t0
        results[name] = {"seconds": seconds, "msg_per_s": args.messages / seconds}
        print(f"{name}: {args.messages / seconds:,.0f} msg/s ({seconds:.2f} s)", flush=True)
    ours = arrays["this project (fast path)"]
    for name in ("rosbags deserialize", "mcap-ros2-support"):
        results[name]["identical_values"] = _same(ours, arrays[name])
    big: dict[str, Any] = {}
    if args.big:
        t0 = time.perf_counter()
        big_bag = write_bag(CACHE / f"throughput_{args.big}", args.big)
        print(f"bag of {args.big} messages ready ({time.perf_counter() - t0:.0f} s)")
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(1, maxtasksperchild=1) as pool:
            seconds, peak_mb, n = pool.apply(_peak, (str(big_bag),))
        big = {"messages": n, "seconds": seconds, "peak_mb": peak_mb, "msg_per_s": n / seconds}
        size = sum(f.stat().st_size for f in big_bag.glob("*.mcap")) / 1e6
        big["bag_mb"] = size
        print(f"{n} messages ({size:.0f} MB bag): {seconds:.1f} s, peak {peak_mb:.0f} MB")
    base = results["this project (fast path)"]["msg_per_s"]
    lines = [
        f"Bag evaluation throughput: {args.messages} messages (JointState, WrenchStamped, "
        "PointStamped; zstd MCAP) into numpy arrays",
        "",
        "| reader | msg/s | vs this project | values identical to this project's |",
        "|---|---|---|---|",
        *[
            f"| {name} | {r['msg_per_s']:,.0f} | {base / r['msg_per_s']:.0f}x slower "
            f"| {'yes' if r.get('identical_values', True) else 'NO'} |"
            if name != "this project (fast path)"
            else f"| {name} | {r['msg_per_s']:,.0f} | - | - |"
            for name, r in results.items()
        ],
        "",
    ]
    if big:
        lines.append(
            f"Fast path on {big['messages']:,} messages ({big['bag_mb']:.0f} MB bag): "
            f"{big['seconds']:.1f} s ({big['msg_per_s']:,.0f} msg/s), peak resident memory "
            f"{big['peak_mb']:.0f} MB (fresh process, imports included)."
        )
    lines += ["", "(`.venv/bin/python benchmarks/bag_throughput.py`)"]
    write_results(args.out, "bag_throughput", lines, {"readers": results, "big": big})
    ok = all(r.get("identical_values", True) for r in results.values())
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
