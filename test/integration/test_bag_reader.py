"""The bag reader on real rosbag2 bags recorded by other projects (test/data/external_bags,
copied with their licenses from ../shared/external/bags; see its README.txt)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.reader import joint_series, open_bag

BAGS = Path(__file__).resolve().parents[1] / "data" / "external_bags"

# bag -> {topic: messages}, every one of them read and deserialized
READABLE = {
    "rosbag2_jazzy_mcap_cdr_test_v7": {"/array_topic": 4, "/test_topic": 3},
    "rosbag2_jazzy_sqlite3_cdr_test_v7": {"/array_topic": 4, "/test_topic": 3},
    "rosbag2_jazzy_mcap_split5_wbag_v4": {
        t * 3: n for t, n in zip("ABCDEFGH", (804, 742, 742, 753, 804, 772, 731, 726), strict=True)
    },
    "rosbag2_jazzy_mcap_legacy_typename_v6": {"topic1": 5},
    "rosbag2_jazzy_mcap_no_metadata_reindex": {"/chatter": 1324 + 1324 + 529},
    "rosbag2_humble_sqlite3_zstd_file_compression_v4": {"/topic": 383, "/rosout": 392},
    "rosbag2_humble_sqlite3_zstd_message_compression_v4": {"/topic": 369, "/rosout": 758},
    "rosbag2parquet_humble_mcap_jointstate_imu_v5": {"/one_shot/joint_state": 1},
    "rosbag2parquet_humble_mcap_base_msgs_v5": {"/one_shot/twist": 1},
    "rosbag2_jazzy_mcap_service_events_v8": {"/test_topic1": 1, "/test_topic2": 1},
}


@pytest.mark.parametrize("name", sorted(READABLE))
def test_real_bags_read_completely(name: str) -> None:
    with open_bag(BAGS / name) as bag:
        for topic, expected in READABLE[name].items():
            assert bag.topics[topic].count == expected
            assert sum(1 for _ in bag.messages([topic])) == expected, topic
        assert not bag.recovered_topics


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_qos_mismatch_is_detected_and_recovered(storage: str) -> None:
    """rosbags alone yields 0 of these 20 messages (metadata QoS != storage QoS)."""
    name = f"rosbag2_jazzy_{storage}_talker_v4_qosmismatch"
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    with Reader(BAGS / name) as plain:
        assert sum(1 for _ in plain.messages()) == 0  # the trap is real
    with open_bag(BAGS / name) as bag:
        texts = [m.data for _, _, m in bag.messages(["/topic"])]
        logs = list(bag.messages(["/rosout"]))
        assert len(texts) == 10 and len(logs) == 10
        assert bag.recovered_topics == {"/topic", "/rosout"}


def test_joint_state_arrays_from_a_humble_mcap() -> None:
    with open_bag(BAGS / "rosbag2parquet_humble_mcap_jointstate_imu_v5") as bag:
        series = joint_series(bag, "/one_shot/joint_state", "joint2")
    assert series.position.tolist() == [-0.5]
    assert np.isfinite(series.stamp_s).all()


def test_clear_errors_name_the_bag_and_topic() -> None:
    with pytest.raises(BagReadError, match="wrong_format") as wrong:
        open_bag(BAGS / "rosbag2_jazzy_mcap_wrong_serialization_format_v6").__enter__()
    assert "salvage" not in str(wrong.value)  # salvage cannot help there: it is not damage
    assert "Only cdr bags can be read" in str(wrong.value)
    with open_bag(BAGS / "rosbag2_foxy_sqlite3_cdr_test_v4") as bag:  # no embedded definitions
        with pytest.raises(BagReadError, match=r"/test_topic: unknown message type test_msgs"):
            list(bag.messages(["/test_topic"]))
        with pytest.raises(BagReadError, match="no topic /joint_states"):
            joint_series(bag, "/joint_states")
        with pytest.raises(BagReadError, match=r"custom_data lacks transparency\.actuator"):
            bag.require_custom("transparency.actuator")
    events = BAGS / "rosbag2_jazzy_mcap_service_events_v8"  # srv event definitions
    with open_bag(events) as bag, pytest.raises(BagReadError, match="_service_event: cannot parse"):
        list(bag.messages(["/test_service1/_service_event"]))
    with pytest.raises(BagReadError, match="no such bag"):
        open_bag(BAGS / "nothing_here")
    with pytest.raises(BagReadError, match="not a bag"):
        open_bag(BAGS / "README.txt")
