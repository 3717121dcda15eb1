"""The harness's Listener: its executor thread survives what other threads do to the node."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator

import pytest

pytest.importorskip("rclpy")
from std_msgs.msg import String
from std_srvs.srv import Trigger

from transparency_ros.ros.harness import Listener
from transparency_ros.ros.services import ServiceCaller

pytestmark = pytest.mark.ros


@pytest.fixture
def frequent_thread_switches() -> Iterator[None]:
    """The GIL handed over every microsecond: the race window of a busy machine, every time
    (the old Listener's thread died within about ten turns, three runs out of three)."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    yield
    sys.setswitchinterval(previous)


def test_subscriptions_destroyed_by_another_thread_leave_the_executor_spinning(
    frequent_thread_switches: None,
) -> None:
    """As the rig and the feel-cage runner do: a subscription made for a measurement, destroyed
    by the caller's thread while the executor thread builds its wait set. rclpy raises
    InvalidHandle there; it killed the thread, and every service call after it timed out."""
    listener = Listener("harness_churn_test")
    with listener as node:
        answered = []

        def on_trigger(_request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
            answered.append(True)
            response.success = True
            return response

        node.create_service(Trigger, "~/ping", on_trigger)
        pub = node.create_publisher(String, "/harness_churn", 10)
        stop = threading.Event()

        def flood() -> None:
            while not stop.is_set():
                pub.publish(String(data="x"))
                time.sleep(0.0002)

        flooder = threading.Thread(target=flood, daemon=True)
        flooder.start()
        try:
            for i in range(200):
                sub = node.create_subscription(String, "/harness_churn", lambda _m: None, 10)
                time.sleep(0.0001 * (i % 7))
                node.destroy_subscription(sub)
                assert listener.failure() is None
        finally:
            stop.set()
            flooder.join()
        reply = ServiceCaller(node, listener.failure)(Trigger, "~/ping", Trigger.Request(), 10.0)
        assert reply.success and answered
        assert listener.failure() is None


def test_a_callback_that_raises_is_named_by_failure() -> None:
    listener = Listener("harness_raise_test")
    with listener as node:

        def on_message(_msg: String) -> None:
            raise ValueError("a bug in a callback")

        node.create_subscription(String, "/harness_raise", on_message, 10)
        pub = node.create_publisher(String, "/harness_raise", 10)
        deadline = time.monotonic() + 10.0
        while listener.failure() is None and time.monotonic() < deadline:
            pub.publish(String(data="x"))
            time.sleep(0.01)
        assert listener.failure() == (
            "harness_raise_test's executor stopped: ValueError: a bug in a callback"
        )
