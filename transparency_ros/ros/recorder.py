"""Record ROS topics into a :class:`~transparency_ros.bag.writer.BagWriter`, as ``ros2 bag
record`` does: serialized messages written as they arrive (raw subscriptions, no
deserialization), the log time being the reception time on the ROS clock. Start and stop are
explicit, so a trial's bag holds that trial only.

Messages go into the open bag from the executor's thread as they arrive, so a recording stopped
by Ctrl-C or SIGTERM keeps everything received up to the signal (the bag writer closes it), and
memory does not grow with the recording's length. A write that fails (a full disk) ends the
recording; :meth:`Recorder.stop` raises it.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile

from transparency_ros.bag.errors import BagWriteError
from transparency_ros.bag.writer import BagWriter


def type_name(msg_class: Any) -> str:
    """'sensor_msgs/msg/JointState' for the rosidl class."""
    package = msg_class.__module__.split(".")[0]
    return f"{package}/msg/{msg_class.__name__}"


class Recorder:
    """``watch``: per topic, a callable that also sees every serialized message as it arrives,
    recording or not (from the executor's thread; one subscription serves both)."""

    def __init__(
        self,
        node: Node,
        topics: Mapping[str, Any],
        depth: int = 2000,
        watch: Mapping[str, Callable[[bytes], None]] | None = None,
    ) -> None:
        self.node = node
        self.watch = dict(watch or {})
        unknown = set(self.watch) - set(topics)
        if unknown:
            raise ValueError(f"watched topics not recorded: {', '.join(sorted(unknown))}")
        self.types = {topic: type_name(cls) for topic, cls in topics.items()}
        self._lock = threading.Lock()
        self._bag: BagWriter | None = None
        self._counts: Counter[str] = Counter()
        self._error: BagWriteError | None = None
        for topic, cls in topics.items():
            node.create_subscription(
                cls, topic, partial(self._on_message, topic), QoSProfile(depth=depth), raw=True
            )

    def _on_message(self, topic: str, data: bytes) -> None:
        now = self.node.get_clock().now().nanoseconds
        watcher = self.watch.get(topic)
        if watcher is not None:
            watcher(data)
        with self._lock:
            if self._bag is None:
                return
            try:
                self._bag.write(topic, now, data)
            except BagWriteError as err:
                self._error, self._bag = err, None  # stop: stop() reports it
                return
            self._counts[topic] += 1

    def start(self, bag: BagWriter) -> None:
        """Write every message of the topics into ``bag`` (open) from now on."""
        for topic, msgtype in self.types.items():
            bag.add(topic, msgtype)
        with self._lock:
            self._counts, self._error = Counter(), None
            self._bag = bag

    def stop(self) -> dict[str, int]:
        """Stop writing; return how many messages of each topic were written (BagWriteError if
        a write failed)."""
        with self._lock:
            self._bag = None
            counts, error = dict(self._counts), self._error
        if error is not None:
            raise error
        return counts
