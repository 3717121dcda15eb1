"""In-process delivery of serialized messages between nodes composed into one process.

rclpy (Jazzy) has no intra-process communication: a message from one node to another in the same
process still goes through DDS, and at 10 kHz that delivery, with the Python around it, costs
more than a core has (``benchmarks/contact_latency.py``, one process: a third of the samples
unanswered). rclcpp solves this with intra-process communication; this is the same idea for the
one stream that needs it, /joint_states from the driver (or any source) to the estimator.

A source calls :func:`publish` with the serialized message: every handler registered here for
that topic on the same rclpy context gets the bytes at once, in the source's thread, and the
bytes then go to DDS as usual for everyone else. A node that registers (the estimator with
``in_process:=true``) receives that topic only this way, not also through DDS (that would be
every sample twice); so it hears only sources in its own process. A handler runs in the
publisher's thread: a slow one slows the publisher.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

Handler = Callable[[bytes], None]

_lock = threading.Lock()
_handlers: dict[tuple[int, str], tuple[Handler, ...]] = {}


def subscribe(context: Any, topic: str, handler: Handler) -> Callable[[], None]:
    """Register ``handler`` for ``topic`` on ``context``; returns the function that removes it."""
    key = (id(context), topic)
    with _lock:
        _handlers[key] = (*_handlers.get(key, ()), handler)

    def unsubscribe() -> None:
        with _lock:
            rest = tuple(h for h in _handlers.get(key, ()) if h is not handler)
            if rest:
                _handlers[key] = rest
            else:
                _handlers.pop(key, None)

    return unsubscribe


def handlers(context: Any, topic: str) -> tuple[Handler, ...]:
    return _handlers.get((id(context), topic), ())


def publish(publisher: Any, context: Any, topic: str, data: bytes) -> None:
    """Hand ``data`` to the in-process handlers of ``topic``, then publish it through DDS.

    A lifecycle publisher that is not active delivers to nobody, as rclpy's does."""
    if not getattr(publisher, "is_activated", True):
        return
    for handler in _handlers.get((id(context), topic), ()):
        handler(data)
    publisher.publish(data)
