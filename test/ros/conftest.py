"""Launch-free ROS fixtures: each test gets its own rclpy Context, shut down afterwards.

Each test's Context is on a domain of its own (and ``ROS_DOMAIN_ID`` says so while the test runs,
for the processes it starts): no participant of an earlier test, nor of a process an earlier test
killed, is ever discovered by a later one. Fast DDS 2.14 can deadlock deleting a participant while
its event thread checks a remote participant's lease (eProsima/Fast-DDS 6502; docs/known_issues.md);
a test that discovers only its own participants has no stale lease to check. A domain forced
with TRANSPARENCY_TEST_DOMAIN_ID (test/conftest.py) is kept for every test.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402

from transparency_ros.rosenv import pick_domain_id, release_domain_id  # noqa: E402


@pytest.fixture
def ros_context(monkeypatch: pytest.MonkeyPatch) -> Iterator[Context]:
    forced = os.environ.get("TRANSPARENCY_TEST_DOMAIN_ID")  # (test/conftest.py: one domain)
    domain = int(forced) if forced else pick_domain_id()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    context = Context()
    try:
        rclpy.init(context=context, domain_id=domain)
        yield context
        rclpy.try_shutdown(context=context)
    finally:
        release_domain_id(domain)  # held from the pick: no concurrent suite takes it meanwhile


class Spinner:
    """An executor spinning the given nodes in a background thread.

    stop() waits until the thread has left the executor: rclpy's Node.destroy_node() busy-waits
    (holding the GIL) while any executor still uses the node, so destroying a node whose
    executor thread is still running deadlocks the test process.
    """

    def __init__(self, context: Context, *nodes: Node) -> None:
        self.executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            self.executor.add_node(node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        # the context may be shut down under a spinning executor at teardown
        with contextlib.suppress(Exception):
            self.executor.spin()

    def stop(self) -> None:
        self.executor.shutdown(timeout_sec=10.0)
        self.thread.join(timeout=10.0)
        if self.thread.is_alive():
            raise RuntimeError("executor thread still running 10 s after shutdown")


def wait_for(condition: Callable[[], Any], timeout_s: float = 5.0, period_s: float = 0.01) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(period_s)
    return bool(condition())
