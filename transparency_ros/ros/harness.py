"""Run a node executable as its own process and watch it from this one, both on loopback.

Used by the demo and the benchmarks: :func:`start_node` starts ``<venv>/bin/<executable>`` as
``ros2 run`` would, with the environment confined to loopback on a domain of its own (this
process joins the same domain); :class:`Listener` is an rclpy context, node and spinning executor
in a background thread, torn down cleanly.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import try_shutdown

from transparency_ros.rosenv import local_ros_env


def start_node(
    executable: str,
    parameters: dict[str, object],
    *,
    extra: Sequence[str] = (),
    quiet: bool = False,
    domain_id: int | None = None,
) -> subprocess.Popen[str]:
    """Start a node of this package as a process; its output is captured (stdout and stderr).

    Without ``domain_id`` a free domain is picked; pass one to put several nodes on the same
    domain. This process joins it (for a :class:`Listener` created afterwards)."""
    env = local_ros_env(domain_id=domain_id)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    args = [str(Path(sys.executable).parent / executable), "--ros-args"]
    for name, value in parameters.items():
        args += ["-p", f"{name}:={value}"]
    args += list(extra)
    return subprocess.Popen(
        args,
        env=env,
        stdout=subprocess.DEVNULL if quiet else subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def stop_node(proc: subprocess.Popen[str], timeout_s: float = 10.0) -> str:
    """SIGINT (what Ctrl-C sends), wait, kill if it hangs; return what it printed."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        output, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        output, _ = proc.communicate()
    return output or ""


def first_exited(procs: dict[str, subprocess.Popen[str]]) -> str | None:
    """Which node process has exited, and how (None while all run)."""
    for name, proc in procs.items():
        if proc.poll() is not None:
            return f"{name} exited with code {proc.returncode}"
    return None


def driver_left_motor_enabled(log: str) -> str | None:
    """The tail of an actuator_driver log that does not report a disabled motor at exit."""
    if log and "motor enabled at exit: False" not in log:
        return "\n".join(log.splitlines()[-15:])
    return None


class Listener:
    """``with Listener("name") as node:`` an rclpy node spinning in a background thread."""

    def __init__(self, name: str) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)

    def __enter__(self) -> Node:
        self._thread.start()
        return self.node

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.executor.shutdown()
        self._thread.join(timeout=5.0)
        self.node.destroy_node()
        try_shutdown(context=self.context)
