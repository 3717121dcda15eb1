"""The fast path of the bag reader (transparency_ros.bag.fast) against rosbags: every numeric
field of every message, bit for bit, on the reference bags, on bags recorded by other projects
and on generated streams; and the fallback where the layout is not fixed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from transparency_ros.bag import reader as reader_module
from transparency_ros.bag.fast import read_fields
from transparency_ros.bag.reader import joint_series, normalise_type, open_bag, scalar_series
from transparency_ros.bag.writer import BagWriter, message_types, time_msg

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = sorted(m.parent for m in (ROOT / "bags").rglob("metadata.yaml"))
EXTERNAL = ROOT / "test" / "data" / "external_bags"


def _value(msg: Any, path: str) -> Any:
    value = msg
    for part in path.replace("]", "").replace("[", ".").split("."):
        value = value[int(part)] if part.isdigit() else getattr(value, part)
    return value


def _check_topic(bag: Any, topic: str) -> bool:
    """Every field the fast path gives equals rosbags' value bit for bit; whether it applied."""
    fields = read_fields(bag.storage_paths, topic, bag.typestore, normalise_type)
    if fields is None:
        return bag.topics[topic].count == 0  # (no messages: nothing to read fast)
    messages = [m for _, _, m in bag.messages([topic])]
    assert fields.log_time_ns.size == len(messages) == bag.topics[topic].count
    assert sorted(fields.log_time_ns) == sorted(t for _, t, _ in bag.messages([topic]))
    # the fast path reads in storage order, rosbags in log-time order: match by log time
    order = np.argsort(fields.log_time_ns, kind="stable")
    for path, values in fields.fields.items():
        expected = np.array([_value(m, path) for m in messages], dtype=values.dtype)
        assert np.array_equal(values[order].view(np.uint8), expected.view(np.uint8)), path
    return True


@pytest.mark.parametrize("bag_dir", REFERENCE, ids=lambda p: p.parent.name + "/" + p.name)
def test_every_field_of_the_reference_bags_equals_rosbags(bag_dir: Path) -> None:
    with open_bag(bag_dir) as bag:
        applied = {topic: _check_topic(bag, topic) for topic in bag.topics}
    # JointState, WrenchStamped and PointStamped streams all take the fast path
    assert all(applied.values()), applied


@pytest.mark.parametrize(
    ("name", "fast"),
    [
        ("rosbag2_jazzy_mcap_cdr_test_v7", True),
        ("rosbag2_jazzy_mcap_legacy_typename_v6", True),
        ("rosbag2parquet_humble_mcap_jointstate_imu_v5", True),
        ("rosbag2parquet_humble_mcap_base_msgs_v5", True),
        # std_msgs/String "Hello, world N": the text changes from message to message
        ("rosbag2_jazzy_mcap_split5_wbag_v4", False),
    ],
)
def test_bags_of_other_projects_equal_rosbags_where_the_fast_path_applies(
    name: str, fast: bool
) -> None:
    with open_bag(EXTERNAL / name) as bag:
        applied = [t for t in bag.topics if _check_topic(bag, t)]
    assert bool(applied) == fast


def _joint_state(t_ns: int, names: list[str], values: list[float]) -> Any:
    types = message_types()
    return types["sensor_msgs/msg/JointState"](
        header=types["std_msgs/msg/Header"](stamp=time_msg(t_ns), frame_id="base"),
        name=names,
        position=np.array(values, dtype=float),
        velocity=np.array([v * 2 for v in values], dtype=float),
        effort=np.array([], dtype=float),
    )


def test_a_stream_whose_layout_changes_falls_back_and_reads_the_same(tmp_path: Path) -> None:
    out = tmp_path / "changing"
    with BagWriter(out) as bag:
        bag.add("/joint_states", "sensor_msgs/msg/JointState")
        for i in range(300):
            # the joint names change length halfway: no fixed layout
            names = ["j"] if i < 150 else ["joint_long_name"]
            bag.write_message("/joint_states", i * 1000, _joint_state(i * 1000, names, [i * 0.5]))
    with open_bag(out) as bag:
        assert read_fields(bag.storage_paths, "/joint_states", bag.typestore) is None
        series = joint_series(bag, "/joint_states")
    assert np.array_equal(series.position, np.arange(300) * 0.5)
    assert np.array_equal(series.velocity, np.arange(300) * 1.0)
    assert np.all(np.isnan(series.effort))


def test_fast_and_deserializing_series_are_identical(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "steady"
    rng = np.random.default_rng(3)
    values = rng.normal(size=(2000, 2))
    with BagWriter(out) as bag:
        bag.add("/joint_states", "sensor_msgs/msg/JointState")
        bag.add("/point", "geometry_msgs/msg/PointStamped")
        types = message_types()
        for i, (a, b) in enumerate(values):
            t = 1_700_000_000_000_000_000 + i * 1_000_003
            bag.write_message("/joint_states", t, _joint_state(t, ["a", "b"], [a, b]))
            point = types["geometry_msgs/msg/PointStamped"](
                header=types["std_msgs/msg/Header"](stamp=time_msg(t), frame_id="w"),
                point=types["geometry_msgs/msg/Point"](x=a, y=b, z=a * b),
            )
            bag.write_message("/point", t, point)
    with open_bag(out) as bag:
        fast = (
            joint_series(bag, "/joint_states", "b"),
            scalar_series(bag, "/point", "geometry_msgs/msg/PointStamped", "point.z"),
        )
        monkeypatch.setattr(reader_module, "read_fields", lambda *a, **k: None)
        slow = (
            joint_series(bag, "/joint_states", "b"),
            scalar_series(bag, "/point", "geometry_msgs/msg/PointStamped", "point.z"),
        )
    for name in ("stamp_ns", "position", "velocity", "effort"):
        a, b = getattr(fast[0], name), getattr(slow[0], name)
        assert np.array_equal(a, b, equal_nan=True), name
    assert np.array_equal(fast[0].position, values[:, 1])
    stamps = [1_700_000_000_000_000_000 + i * 1_000_003 for i in range(len(values))]
    assert fast[0].stamp_ns.tolist() == stamps  # exact integer nanoseconds, both paths
    assert fast[1].stamp_ns.tolist() == slow[1].stamp_ns.tolist() == stamps
    assert np.array_equal(fast[1].value, slow[1].value)


def test_messages_outside_chunks_are_not_skipped(tmp_path: Path) -> None:
    """An MCAP file written without chunks: the fast path reads chunks only, so it must step
    aside (not return a silently short stream); rosbags reads the messages."""
    from mcap.writer import Writer  # noqa: PLC0415

    from transparency_ros.bag.writer import TYPESTORE  # noqa: PLC0415

    path = tmp_path / "unchunked.mcap"
    with path.open("wb") as f:
        writer = Writer(f, use_chunking=False)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(
            "sensor_msgs/msg/JointState", "ros2msg", b"# (known to the typestore)"
        )
        channel = writer.register_channel("/joint_states", "cdr", schema)
        for i in range(20):
            data = TYPESTORE.serialize_cdr(
                _joint_state(i * 1000, ["j"], [float(i)]), "sensor_msgs/msg/JointState"
            )
            writer.add_message(channel, log_time=i * 1000, data=bytes(data), publish_time=i)
        writer.finish()
    with open_bag(path) as bag:
        assert read_fields(bag.storage_paths, "/joint_states", bag.typestore) is None
        series = joint_series(bag, "/joint_states")
    assert np.array_equal(series.position, np.arange(20.0))


def test_large_messages_such_as_images_are_left_to_rosbags(tmp_path: Path) -> None:
    out = tmp_path / "images"
    types = message_types()
    with BagWriter(out) as bag:
        bag.add("/image", "sensor_msgs/msg/Image")
        for i in range(3):
            image = types["sensor_msgs/msg/Image"](
                header=types["std_msgs/msg/Header"](stamp=time_msg(i), frame_id="cam"),
                height=16,
                width=16,
                encoding="mono8",
                is_bigendian=0,
                step=16,
                data=np.full(256, i, dtype=np.uint8),
            )
            bag.write_message("/image", i, image)
    with open_bag(out) as bag:
        assert read_fields(bag.storage_paths, "/image", bag.typestore) is None
