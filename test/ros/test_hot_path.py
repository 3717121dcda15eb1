"""ros.hot_path: raw subscriptions served by a thread of their own, out of every executor."""

from __future__ import annotations

import os

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState

from test.ros.conftest import wait_for
from transparency_ros.core.cdr import decode_joint_state, encode_joint_state
from transparency_ros.ros.hot_path import HotPath

pytestmark = pytest.mark.ros


def test_a_failing_handler_is_counted_and_the_thread_goes_on(ros_context: Context) -> None:
    node = Node("hot_path_test", context=ros_context)
    got: list[int] = []

    def handler(data: bytes) -> None:
        sec = decode_joint_state(data).sec
        if sec == 2:
            raise RuntimeError("a handler bug")
        got.append(sec)

    hot = HotPath(node)
    sub = hot.subscribe(JointState, "/hot_path_test", 10, handler)
    hot.start()
    with pytest.raises(RuntimeError, match="before start"):
        hot.subscribe(JointState, "/too_late", 10, handler)
    # no executor serves the subscription, even with the node added to one
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    assert not executor.can_execute(sub)
    pub = node.create_publisher(JointState, "/hot_path_test", 10)
    try:
        assert wait_for(lambda: pub.get_subscription_count() == 1)
        for sec in (1, 2, 3):
            pub.publish(encode_joint_state(sec, 0, "", ["j"], position=[0.0]))
        assert wait_for(lambda: got == [1, 3])
        assert hot.handler_errors == 1
    finally:
        hot.stop()
        executor.shutdown()
        node.destroy_node()
    assert hot._thread is not None and not hot._thread.is_alive()


def test_the_thread_ends_when_the_context_shuts_down() -> None:
    context = Context()
    rclpy.init(context=context)  # on the session's loopback domain (test/conftest.py)
    node = Node("hot_path_shutdown", context=context)
    hot = HotPath(node)
    hot.subscribe(JointState, "/hot_path_shutdown", 10, lambda data: None)
    hot.start()
    rclpy.shutdown(context=context)
    assert hot._thread is not None
    hot._thread.join(timeout=2.0)
    assert not hot._thread.is_alive()


def test_priority_is_sched_fifo_or_a_stated_refusal(ros_context: Context) -> None:
    node = Node("hot_path_priority", context=ros_context)
    hot = HotPath(node, priority=10)
    hot.subscribe(JointState, "/hot_path_priority", 10, lambda data: None)
    hot.start()
    try:
        assert hot._thread is not None
        assert wait_for(lambda: hot._thread.native_id is not None)  # type: ignore[union-attr]
        native = hot._thread.native_id
        assert native is not None
        assert wait_for(
            lambda: hot.priority_error or os.sched_getscheduler(native) == os.SCHED_FIFO
        )
        if hot.priority_error:  # without CAP_SYS_NICE or an rtprio limit
            assert "SCHED_FIFO 10 refused" in hot.priority_error
        else:
            assert os.sched_getparam(native).sched_priority == 10
    finally:
        # a thread still running would make destroy_node hang (it did once in a full run)
        assert hot.stop(), "the hot path thread did not stop within 5 s"
        node.destroy_node()
