"""SIGTERM handled like Ctrl-C, and signals held back while a file is being finished.

A recorder must leave a bag that opens whichever way it is stopped. Ctrl-C raises
``KeyboardInterrupt``, which unwinds through ``with`` blocks and ``finally`` clauses, so bags are
closed and node processes stopped. SIGTERM (``kill``, systemd, a CI timeout) ends a Python
process on the spot by default; :func:`terminate_like_interrupt` makes it raise
:class:`Terminated` instead, a ``KeyboardInterrupt`` subclass, so the same clean-up runs.

:func:`interrupt_on_sigint` makes SIGINT raise ``KeyboardInterrupt`` even where the process was
started with SIGINT ignored (the background of a script: shells without job control start
such processes so). rclpy shuts its contexts down on SIGINT whatever Python's disposition, so a
command that ignored it would go on with dead contexts; it unwinds as for Ctrl-C instead.

:func:`deferred_interrupts` holds SIGINT and SIGTERM back while a file is being finished (a
second Ctrl-C during the close must not leave half a bag); they are raised when the block ends.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised as Ctrl-C's ``KeyboardInterrupt`` is, so the same clean-up runs."""


def interruption_name(exc: BaseException) -> str:
    """'SIGTERM' or 'SIGINT' for the exception an interruption raised."""
    return "SIGTERM" if isinstance(exc, Terminated) else "SIGINT"


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated(f"signal {signal.Signals(signum).name}")


def terminate_like_interrupt() -> None:
    """Make SIGTERM raise :class:`Terminated` in the main thread (call from the main thread)."""
    signal.signal(signal.SIGTERM, _raise_terminated)


def interrupt_on_sigint() -> Any:
    """SIGINT raises ``KeyboardInterrupt`` (Python's default handler), also when the process
    started with it ignored; returns the previous handler (call from the main thread)."""
    return signal.signal(signal.SIGINT, signal.default_int_handler)


def _raise_for(signum: int) -> None:
    if signum == signal.SIGTERM:
        raise Terminated("signal SIGTERM")
    raise KeyboardInterrupt


@contextmanager
def deferred_interrupts() -> Iterator[None]:
    """SIGINT and SIGTERM arriving in the block take effect when it ends (the first one).

    Only the main thread can install signal handlers; elsewhere (where Python never runs them
    anyway) this does nothing. Handlers installed below Python (rclpy's, which shut its contexts
    down and then call Python's) are not restored: afterwards the signal goes to Python's
    handler directly, and the clean-up it unwinds through shuts the contexts down instead."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []

    def hold(signum: int, frame: FrameType | None) -> None:
        held.append(signum)

    previous: dict[int, Any] = {s: signal.signal(s, hold) for s in SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if held:
        handler = previous[held[0]]
        if callable(handler) and handler not in (signal.default_int_handler, _raise_terminated):
            handler(held[0], None)
        elif handler == signal.SIG_IGN:
            return
        else:
            _raise_for(held[0])
