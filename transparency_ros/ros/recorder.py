"""Record ROS topics into a :class:`~transparency_ros.bag.writer.BagWriter`, as ``ros2 bag
record`` would: serialized messages as they arrive (raw subscriptions, no deserialization), the
log time being the reception time on the ROS clock. Start and stop are explicit, so a trial's bag
holds that trial only."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from functools import partial
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile

from transparency_ros.bag.writer import BagWriter


def type_name(msg_class: Any) -> str:
    """'sensor_msgs/msg/JointState' for the rosidl class."""
    package = msg_class.__module__.split(".")[0]
    return f"{package}/msg/{msg_class.__name__}"


class Recorder:
    def __init__(self, node: Node, topics: Mapping[str, Any], depth: int = 2000) -> None:
        self.node = node
        self.types = {topic: type_name(cls) for topic, cls in topics.items()}
        self._lock = threading.Lock()
        self._recording = False
        self._messages: list[tuple[str, int, bytes]] = []
        for topic, cls in topics.items():
            node.create_subscription(
                cls, topic, partial(self._on_message, topic), QoSProfile(depth=depth), raw=True
            )

    def _on_message(self, topic: str, data: bytes) -> None:
        now = self.node.get_clock().now().nanoseconds
        with self._lock:
            if self._recording:
                self._messages.append((topic, now, bytes(data)))

    def start(self) -> None:
        with self._lock:
            self._messages = []
            self._recording = True

    def stop(self) -> list[tuple[str, int, bytes]]:
        """Stop and return what was recorded: (topic, log time [ns], CDR bytes)."""
        with self._lock:
            self._recording = False
            messages, self._messages = self._messages, []
        return messages

    def write_into(self, bag: BagWriter, messages: list[tuple[str, int, bytes]]) -> None:
        for topic, msgtype in self.types.items():
            bag.add(topic, msgtype)
        for topic, log_ns, data in messages:
            bag.write(topic, log_ns, data)
