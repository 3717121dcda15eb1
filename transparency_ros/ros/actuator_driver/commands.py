"""/joint_commands into the driver's cores (a part of :class:`ActuatorDriverNode`): decoded from
the raw bytes its hot path takes, checked, clamped and set as targets; everything refused is
counted on the cores it was meant for and warned about at most once a second."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from transparency_ros.canbus.clock import ClockOffset
from transparency_ros.canbus.multi import MultiControlLoop
from transparency_ros.core.cdr import CdrError, JointStateFields, JointStateReader
from transparency_ros.core.driver import CommandRejectedError, DriverCore, parse_joint_command


class CommandInput:
    """The command path of the driver node; the node provides the attributes below."""

    loop: Any
    core: DriverCore
    values: dict[str, Any]
    _to_ros: ClockOffset
    _warn_throttled: Callable[[str], None]

    def _core_lock(self) -> Any:
        return self.loop.lock if self.loop is not None else threading.RLock()

    def _reject(self, reason: str, cores: Sequence[DriverCore] | None = None) -> None:
        """Count a refused command on ``cores`` (default: every motor's) and warn."""
        loop = self.loop
        if cores is None:
            cores = [m.core for m in loop.motors] if isinstance(loop, MultiControlLoop) else [
                self.core]  # fmt: skip
        with self._core_lock():
            for core in cores:
                core.reject(reason)
        self._warn_throttled(f"rejected /joint_commands: {reason}")

    def _on_command_bytes(self, reader: JointStateReader, data: bytes) -> None:
        try:
            msg = reader(data)
        except CdrError as err:
            self._reject(f"undecodable message: {err}")
            return
        self._on_command(msg)

    def _on_command(self, msg: JointStateFields) -> None:
        now = time.monotonic()
        stamp = msg.stamp_ns * 1e-9
        if stamp > 0:
            # a stamped command holds from its stamp on (streamed trajectories are extrapolated
            # from there, so transport latency does not make the joint lag)
            age = now - self._to_ros.back(stamp)
            if 0.0 <= age < 1.0:
                now -= age
        if isinstance(self.loop, MultiControlLoop):
            self._on_motors_command(msg, now)
            return
        try:
            target = parse_joint_command(
                self.values["joint_name"], msg.name, msg.position, msg.velocity, msg.effort
            )
        except CommandRejectedError as err:
            self._reject(str(err))
            return
        with self._core_lock():
            clamped = self.core.set_target(target, now)
        if clamped:
            self._warn_throttled("command clamped to the configured limits")

    def _on_motors_command(self, msg: JointStateFields, now: float) -> None:
        """A command for several motors: by name, all or nothing (one bad joint rejects the
        message); joints of other drivers are ignored, motors not named keep their target."""
        loop = self.loop
        assert isinstance(loop, MultiControlLoop)
        named = [m for m in loop.motors if m.name in msg.name]
        try:
            if not msg.name:
                raise CommandRejectedError("commands for several motors need joint names")
            if not named:
                raise CommandRejectedError(
                    f"none of {[m.name for m in loop.motors]} in command names {list(msg.name)}"
                )
            targets = [
                parse_joint_command(m.name, msg.name, msg.position, msg.velocity, msg.effort)
                for m in named
            ]
        except CommandRejectedError as err:
            self._reject(str(err), [m.core for m in named] or None)
            return
        with loop.lock:
            clamped = [m.core.set_target(t, now) for m, t in zip(named, targets, strict=True)]
        if any(clamped):
            self._warn_throttled("command clamped to the configured limits")
