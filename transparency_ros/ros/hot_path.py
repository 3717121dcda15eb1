"""A node's high-rate subscriptions, served as serialized bytes from a thread of their own.

rclpy's executors rebuild a wait set from every entity of every node on each wake-up (the
estimator alone has 13: its subscriptions, timer, reset service, six parameter services, the
type-description service and guard conditions) and wrap each callback in a task; rclpy then
turns each message into a Python object. Measured on the benchmark machine at 1 kHz, an echo
node's round trip had a median of 0.56 ms and a p99 of 1.2 ms on the ``SingleThreadedExecutor``
with message objects, against 0.38 ms and 0.62 ms with a plain wait on its one subscription and
raw bytes (``benchmarks/contact_latency.py`` measures the nodes themselves).

:class:`HotPath` therefore creates its subscriptions with ``raw=True`` in a callback group that
no executor serves (:class:`Unserved`), and a thread of its own waits on just those and hands
each message's bytes to the handler. Everything else on the node (parameters, services, timers,
low-rate subscriptions) stays with whatever executor the node is added to, so the node composes
with any executor. Handlers run on the hot-path thread: state they share with executor callbacks
needs a lock.

rclpy (Jazzy) has no public wait-set class; the thread uses the one its executors use
(``rclpy.impl.implementation_singleton.rclpy_implementation.WaitSet``), the same way they do.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
import traceback
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.exceptions import InvalidHandle
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile

Handler = Callable[[bytes], None]
WAKE_CHECK_NS = 500_000_000  # a shut-down context is noticed within this even if nothing wakes


class Unserved(CallbackGroup):
    """A callback group no executor runs: its entities are served by a :class:`HotPath`."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


@dataclass
class Delivery:
    """What reached a subscription, and what the DDS layer lost on the way, from the
    publication sequence numbers: a gap is samples the publisher sent that never arrived (the
    subscription's queue overflowed in a burst, or the network dropped them). Counted from the
    first sample received (what came before it may have been sent before the subscription
    matched). Exact for one publisher; with several, their numbers interleave (the estimator
    then reports the loss as unknown)."""

    received: int = 0
    lost: int = 0
    last: int | None = None

    def note(self, sequence: int | None) -> None:
        self.received += 1
        if sequence is None:  # an RMW without sequence numbers
            return
        # (a sequence going back: a new publisher, or several interleaved; not a loss)
        if self.last is not None and sequence > self.last + 1:
            self.lost += sequence - self.last - 1
        self.last = sequence

    def reset(self) -> None:
        self.received = self.lost = 0


class HotPath:
    """Raw subscriptions of ``node`` served by one thread; :meth:`start` after adding them,
    :meth:`stop` before destroying the node (also done when the context shuts down)."""

    def __init__(self, node: Node, priority: int = 0) -> None:
        self.node = node
        self.priority = priority  # SCHED_FIFO priority of the thread (0: normal scheduling)
        self.priority_error = ""  # why the priority could not be set
        self.group = Unserved()
        self._subs: list[tuple[Any, Handler, Delivery]] = []
        self._wake = GuardCondition(None, None, context=node.context)
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self.handler_errors = 0
        self._last_error_log = -1e9
        node.context.on_shutdown(self._stop_at_shutdown)

    def subscribe(self, msg_type: Any, topic: str, qos: QoSProfile | int, handler: Handler) -> Any:
        if self._thread is not None:
            raise RuntimeError("HotPath: subscribe before start()")
        sub = self.node.create_subscription(
            msg_type, topic, lambda _msg: None, qos, callback_group=self.group, raw=True
        )
        self._subs.append((sub, handler, Delivery()))
        return sub

    def delivery(self, sub: Any) -> Delivery:
        """The delivery counts of a subscription made by :meth:`subscribe` (read them under
        the lock the handler takes, or accept a sample's worth of skew)."""
        return next(d for s, _, d in self._subs if s is sub)

    def start(self) -> None:
        self._thread = threading.Thread(
            target=self._run, name=f"{self.node.get_name()} hot path", daemon=True
        )
        self._thread.start()

    def _stop_at_shutdown(self) -> None:
        self.stop()

    def stop(self) -> bool:
        """Stop the thread and wait for it (not from a handler); idempotent. False when it is
        still running after 5 s: then the node must not be destroyed (rclpy's destroy_node
        busy-waits, holding the GIL, while the thread holds the subscription's handle)."""
        self._stopping.set()
        # the context may be gone already; then the wait's timeout ends it
        with contextlib.suppress(Exception):
            self._wake.trigger()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=5.0)
            return not thread.is_alive()
        return True

    def _set_priority(self) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
        except (OSError, AttributeError) as err:  # no CAP_SYS_NICE / rtprio limit; not Linux
            self.priority_error = f"SCHED_FIFO {self.priority} refused ({err}); normal scheduling"
            self.node.get_logger().warning(f"hot path: {self.priority_error}")

    def _run(self) -> None:
        if self.priority > 0:
            self._set_priority()
        context = self.node.context
        wait_set = None
        while not self._stopping.is_set() and context.ok():
            try:
                with ExitStack() as held:
                    for sub, _, _ in self._subs:
                        held.enter_context(sub.handle)
                    held.enter_context(self._wake.handle)
                    handle = context.handle
                    assert handle is not None
                    held.enter_context(handle)
                    if wait_set is None:
                        wait_set = _rclpy.WaitSet(len(self._subs), 1, 0, 0, 0, 0, handle)
                    wait_set.clear_entities()
                    for sub, _, _ in self._subs:
                        wait_set.add_subscription(sub.handle)
                    wait_set.add_guard_condition(self._wake.handle)
                    wait_set.wait(WAKE_CHECK_NS)
                    if self._stopping.is_set():
                        return
                    for sub, handler, delivery in self._subs:
                        while (taken := sub.handle.take_message(sub.msg_type, True)) is not None:
                            delivery.note(taken[1].get("publication_sequence_number"))
                            self._call(handler, taken[0])
            except InvalidHandle:
                return  # the node is being destroyed
            except Exception:
                if self._stopping.is_set() or not context.ok():  # it went down under us
                    return
                raise

    def guarded(self, handler: Handler) -> Handler:
        """``handler`` with its errors logged and counted as on the hot path (for handlers that
        run elsewhere, such as ``ros.in_process`` deliveries in a source's thread)."""
        return lambda data: self._call(handler, data)

    def _call(self, handler: Handler, data: bytes) -> None:
        try:
            handler(data)
        except Exception:  # noqa: BLE001 - a bad message must not end the thread
            if self._stopping.is_set() or not self.node.context.ok():
                return  # a signal shut the context down under the handler: it is stopping
            self.handler_errors += 1
            now = time.monotonic()
            if now - self._last_error_log >= 1.0:
                self._last_error_log = now
                self.node.get_logger().error(
                    f"hot-path handler failed ({self.handler_errors} so far):\n"
                    + traceback.format_exc()
                )
