"""ros.in_process: delivery to handlers on the same context and topic, then DDS for the rest."""

from __future__ import annotations

from typing import Any

import pytest
from rclpy.context import Context
from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node
from sensor_msgs.msg import JointState

from test.ros.conftest import Spinner, wait_for
from transparency_ros.core.cdr import decode_joint_state, encode_joint_state
from transparency_ros.ros import in_process

pytestmark = pytest.mark.ros


def test_handlers_of_the_topic_and_context_get_the_bytes_then_dds(ros_context: Context) -> None:
    node = Node("in_process_test", context=ros_context)
    pub = node.create_publisher(JointState, "/in_process_test", 10)
    through_dds: list[Any] = []
    node.create_subscription(JointState, "/in_process_test", through_dds.append, 10)
    spinner = Spinner(ros_context, node)
    got: list[bytes] = []
    other: list[bytes] = []
    leave = in_process.subscribe(ros_context, "/in_process_test", got.append)
    leave_other = in_process.subscribe(ros_context, "/another_topic", other.append)
    try:
        assert wait_for(lambda: pub.get_subscription_count() == 1)
        data = encode_joint_state(1, 2, "", ["j"], position=[0.5])
        in_process.publish(pub, ros_context, "/in_process_test", data)
        assert got == [data] and other == []  # at once, in this thread
        assert wait_for(lambda: len(through_dds) == 1)
        assert list(through_dds[0].position) == [0.5]
        leave()
        in_process.publish(pub, ros_context, "/in_process_test", data)
        assert got == [data]
        assert in_process.handlers(ros_context, "/in_process_test") == ()
        assert wait_for(lambda: len(through_dds) == 2)
    finally:
        leave_other()
        spinner.stop()
        node.destroy_node()


def test_an_inactive_lifecycle_publisher_delivers_nothing(ros_context: Context) -> None:
    node = LifecycleNode("in_process_lifecycle", context=ros_context)
    pub = node.create_lifecycle_publisher(JointState, "/in_process_lc", 10)
    got: list[bytes] = []
    leave = in_process.subscribe(ros_context, "/in_process_lc", got.append)
    try:
        data = encode_joint_state(3, 0, "", ["j"], position=[1.0])
        in_process.publish(pub, ros_context, "/in_process_lc", data)
        assert got == []
        pub.on_activate(None)
        in_process.publish(pub, ros_context, "/in_process_lc", data)
        assert [decode_joint_state(d).sec for d in got] == [3]
    finally:
        leave()
        node.destroy_node()
