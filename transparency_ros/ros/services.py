"""Service calls from a runner that steers node processes (feel-cage runner, drop rig)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rclpy.node import Node

from transparency_ros.core.errors import TransparencyError

CALL_ATTEMPT_S = 2.0


class ServiceCallError(TransparencyError, RuntimeError):
    """A service that did not come up or answer, or a node process that died."""


def wait_until(condition: Callable[[], Any], timeout_s: float, poll_s: float = 0.005) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(poll_s)
    return bool(condition())


class ServiceCaller:
    """Service calls with retries: rmw_fastrtps drops a response when the client's response
    reader is not matched on the server side within 100 ms (ros2/rmw_fastrtps#390, #467), which
    happens on a busy machine. One client per service, kept so it matches once; callers only make
    requests that are idempotent or harmless to repeat. ``died`` names a node process that
    exited (checked before every call and by :meth:`check`)."""

    def __init__(self, node: Node, died: Callable[[], str | None] = lambda: None) -> None:
        self.node, self.died = node, died
        self.clients: dict[str, Any] = {}

    def check(self) -> None:
        reason = self.died()
        if reason:
            raise ServiceCallError(reason)

    def __call__(self, srv: Any, name: str, request: Any, timeout_s: float = 15.0) -> Any:
        self.check()
        client = self.clients.get(name)
        if client is None:
            client = self.clients[name] = self.node.create_client(srv, name)
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise ServiceCallError(f"service {name} did not come up within {timeout_s:.0f} s")
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            future = client.call_async(request)
            if wait_until(future.done, min(CALL_ATTEMPT_S, max(0.0, deadline - time.monotonic()))):
                return future.result()
            client.remove_pending_request(future)
            self.check()
        raise ServiceCallError(f"service {name} did not answer within {timeout_s:.0f} s")
