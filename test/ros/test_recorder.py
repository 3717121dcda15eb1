"""The recorder: every message received goes into the bag, however the recording ends."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import JointState

from test.ros.conftest import Spinner, wait_for
from transparency_ros.bag.errors import BagWriteError
from transparency_ros.bag.keys import INTERRUPTED_KEY
from transparency_ros.bag.reader import joint_series, open_bag
from transparency_ros.bag.writer import BagWriter
from transparency_ros.core.cdr import header_stamp_ns
from transparency_ros.core.interrupts import Terminated, terminate_like_interrupt
from transparency_ros.ros.recorder import Recorder

pytestmark = pytest.mark.ros
N = 400


def _publish(node: Node, count: int) -> None:
    pub = node.create_publisher(JointState, "/joint_states", 10)
    assert wait_for(lambda: pub.get_subscription_count() > 0)
    for i in range(count):
        msg = JointState(name=["joint"], position=[float(i)])
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1, i
        pub.publish(msg)
        time.sleep(0.0005)


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM"])
def test_a_signal_keeps_every_message_received(
    sigint_raises: None, ros_context: Context, tmp_path: Path, how: str
) -> None:
    node = Node("recorder_test", context=ros_context)
    recorder = Recorder(node, {"/joint_states": JointState})
    spinner = Spinner(ros_context, node)
    previous = signal.getsignal(signal.SIGTERM)
    terminate_like_interrupt()
    counts: dict[str, int] = {}

    def record_until_signal() -> None:
        with BagWriter(tmp_path / "bag") as bag:
            recorder.start(bag)
            try:
                _publish(node, N)
                assert wait_for(lambda: bag.count == N)
                os.kill(os.getpid(), signal.Signals[how])  # as `kill` or Ctrl-C would
                time.sleep(5.0)
            finally:
                counts.update(recorder.stop())

    try:
        with pytest.raises(Terminated if how == "SIGTERM" else KeyboardInterrupt):
            record_until_signal()
    finally:
        signal.signal(signal.SIGTERM, previous)
        spinner.stop()
        node.destroy_node()
    assert counts == {"/joint_states": N}
    with open_bag(tmp_path / "bag") as kept:
        assert kept.custom_data[INTERRUPTED_KEY] == how
        series = joint_series(kept, "/joint_states")
    assert series.position.tolist() == [float(i) for i in range(N)]  # every one, in order


def test_a_failing_write_stops_the_recording_and_is_reported(
    ros_context: Context, tmp_path: Path
) -> None:
    node = Node("recorder_test", context=ros_context)
    recorder = Recorder(node, {"/joint_states": JointState})
    spinner = Spinner(ros_context, node)
    try:
        with BagWriter(tmp_path / "bag") as bag:
            recorder.start(bag)
            bag._connections.clear()  # any failing write, as a full disk gives
            _publish(node, 3)
            time.sleep(0.5)
            with pytest.raises(BagWriteError, match="/joint_states"):
                recorder.stop()
    finally:
        spinner.stop()
        node.destroy_node()


def test_a_watcher_sees_every_message_recording_or_not(
    ros_context: Context, tmp_path: Path
) -> None:
    node = Node("recorder_test", context=ros_context)
    seen: list[bytes] = []
    recorder = Recorder(node, {"/joint_states": JointState}, watch={"/joint_states": seen.append})
    spinner = Spinner(ros_context, node)
    try:
        _publish(node, 5)  # not recording
        assert wait_for(lambda: len(seen) == 5)
        with BagWriter(tmp_path / "bag") as bag:
            recorder.start(bag)
            _publish(node, 3)
            assert wait_for(lambda: len(seen) == 8)
            assert recorder.stop() == {"/joint_states": 3}
    finally:
        spinner.stop()
        node.destroy_node()
    assert [header_stamp_ns(data) - 10**9 for data in seen] == [0, 1, 2, 3, 4, 0, 1, 2]


def test_a_watched_topic_that_is_not_recorded_is_refused(ros_context: Context) -> None:
    node = Node("recorder_test", context=ros_context)
    try:
        with pytest.raises(ValueError, match="watched topics not recorded: /contact"):
            Recorder(node, {"/joint_states": JointState}, watch={"/contact": print})
    finally:
        node.destroy_node()
