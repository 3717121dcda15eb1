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
from rclpy.exceptions import InvalidHandle
from rclpy.executors import ExternalShutdownException, ShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import try_shutdown

from transparency_ros.rosenv import local_ros_env, release_domain_id

# the domain start_node picked for a process, released when stop_node has stopped it
_picked_for: dict[int, int] = {}


def start_node(
    executable: str,
    parameters: dict[str, object],
    *,
    extra: Sequence[str] = (),
    quiet: bool = False,
    domain_id: int | None = None,
) -> subprocess.Popen[str]:
    """Start a node of this package as a process; its output is captured (stdout and stderr).

    Without ``domain_id`` a free domain is picked, held until :func:`stop_node` stops the
    process; pass one to put several nodes on the same domain (the caller holds it). This
    process joins it (for a :class:`Listener` created afterwards)."""
    env = local_ros_env(domain_id=domain_id)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    args = [str(Path(sys.executable).parent / executable), "--ros-args"]
    for name, value in parameters.items():
        args += ["-p", f"{name}:={value}"]
    args += list(extra)
    try:
        proc = subprocess.Popen(
            args,
            env=env,
            stdout=subprocess.DEVNULL if quiet else subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
    except BaseException:
        if domain_id is None:
            release_domain_id(int(env["ROS_DOMAIN_ID"]))
        raise
    if domain_id is None:
        _picked_for[proc.pid] = int(env["ROS_DOMAIN_ID"])
    return proc


def stop_node(proc: subprocess.Popen[str], timeout_s: float = 10.0) -> str:
    """SIGINT (what Ctrl-C sends), wait, kill if it hangs; return what it printed."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        output, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        output, _ = proc.communicate()
    domain = _picked_for.pop(proc.pid, None)
    if domain is not None:
        release_domain_id(domain)
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
    """``with Listener("name") as node:`` an rclpy node spinning in a background thread.

    The thread spins turn by turn until the block ends; only then is the executor shut down and
    the node destroyed (rclpy's executor must not be shut down under a spinning thread: it
    clears its guard condition while the thread still triggers it). An entity destroyed by the
    caller's thread while the executor builds its wait set raises InvalidHandle there, which
    rclpy does not catch; the turn is dropped and the next leaves the entity out (the thread
    used to die of it, and every service call after it timed out). Any other exception from a
    callback stops the thread: :meth:`failure` names it, for the caller's checks."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        # wakes the thread's wait at the block's end (a wait with a timeout would cost an rcl
        # timer per wait set: measurable CPU at 1 kHz)
        self._wake = self.node.create_guard_condition(lambda: None)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._spin, name=f"{name} executor", daemon=True)

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            try:
                self.executor.spin_once()
            except InvalidHandle:
                continue  # an entity destroyed meanwhile: gone from the next wait set
            except (ExternalShutdownException, ShutdownException):
                return
            except Exception as err:  # noqa: BLE001 - kept for failure(), the caller decides
                self._error = err
                return

    def failure(self) -> str | None:
        """Why the executor thread stopped before the block ended (None while it spins)."""
        if self._error is not None:
            return f"{self.name}'s executor stopped: {type(self._error).__name__}: {self._error}"
        if (
            self._thread.ident is not None
            and not self._thread.is_alive()
            and not self._stop.is_set()
        ):
            return f"{self.name}'s executor stopped (context shut down)"
        return None

    def __enter__(self) -> Node:
        self._thread.start()
        return self.node

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._wake.trigger()
        self._thread.join(timeout=10.0)
        self.executor.shutdown(timeout_sec=1.0)
        if not self._thread.is_alive():  # destroying a node in use by a spinning executor hangs
            self.node.destroy_node()
        try_shutdown(context=self.context)
