"""Session-wide test setup.

Every ROS process a test starts (in-process rclpy contexts and subprocesses alike) inherits this
environment: discovery confined to loopback and a domain ID chosen for this session only, never
the caller's (a developer's shell may point at a live robot). It is set at import time, before
any test module can import rclpy. A test with ``ros_context`` (test/ros/conftest.py) moves to a
domain of its own for its duration. Set TRANSPARENCY_TEST_DOMAIN_ID to force one domain for all.

Signals: the suite passes however it is started. A shell without job control (a script's
background job, ``nohup ... &``) starts pytest with SIGINT ignored, and an ignored signal stays
ignored across fork and exec: the processes the tests start and stop with SIGINT (``bag_replay``,
``transparency rig``) would never see it. So SIGINT gets Python's handler here, for the session:
a handled signal is reset to its default on exec, so every child starts with SIGINT at its
default; tests that raise SIGINT in this process also take ``sigint_raises``. SIGTERM (``kill``,
a CI runner's cancel) raises KeyboardInterrupt, so the run stops as after Ctrl-C: each test's
``finally`` and fixtures stop the nodes it started. With Python's default the process died at
once and a driver node a test had started ran on, publishing, after the suite had gone.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator

import pytest

from transparency_ros.rosenv import local_ros_env

_forced = os.environ.get("TRANSPARENCY_TEST_DOMAIN_ID")
os.environ.update(local_ros_env(domain_id=int(_forced) if _forced else None))
os.environ.setdefault("MPLBACKEND", "Agg")

_SIGINT_AT_START = "ignored" if signal.getsignal(signal.SIGINT) == signal.SIG_IGN else "handled"
if _SIGINT_AT_START == "ignored":
    signal.signal(signal.SIGINT, signal.default_int_handler)


def _terminated(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")


signal.signal(signal.SIGTERM, _terminated)


def pytest_report_header() -> str:
    if _SIGINT_AT_START == "ignored":
        return "SIGINT at session start: ignored (Python's handler set for the session)"
    return "SIGINT at session start: handled"


@pytest.fixture
def sigint_raises() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt in this process for the test (Python's handler), as an
    interactive start gives; the handler before is restored afterwards."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
