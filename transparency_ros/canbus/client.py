"""An actuator client on a python-can bus: frames out, feedback in, counters for diagnostics.

The bus is opened from explicit settings (interface, channel, bitrate, fd), so socketcan, pcan,
kvaser, slcan, gs_usb and virtual all work unchanged. Nothing here picks an interface by itself.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import can

from transparency_ros.canbus.errors import BusError, MalformedFrameError
from transparency_ros.canbus.protocol import ActuatorProtocol, Feedback, Frame

# Interfaces that would leave this machine; refused so tests and demos stay on loopback.
FORBIDDEN_INTERFACES = frozenset({"udp_multicast"})
# A frame timestamp within this of time.time() is taken as epoch-based (socketcan, virtual);
# interfaces with another time base (some vendor drivers count from power-up) are not used.
EPOCH_TOLERANCE_S = 10.0


@dataclass(frozen=True)
class BusSettings:
    interface: str = "virtual"
    channel: str = "transparency_sim"
    bitrate: int = 1_000_000
    fd: bool = False
    data_bitrate: int = 0  # CAN-FD data phase; 0 = interface default

    def open(self, *, preserve_timestamps: bool = False) -> can.BusABC:
        """Open the bus. ``preserve_timestamps`` (virtual only): frames keep the timestamp the
        sender set (the simulated device stamps replies with the time it produced them)."""
        if self.interface in FORBIDDEN_INTERFACES:
            raise BusError(f"CAN interface {self.interface!r} is a network transport; refused")
        kwargs: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if preserve_timestamps and self.interface == "virtual":
            kwargs["preserve_timestamps"] = True
        if self.interface != "virtual":
            kwargs["bitrate"] = self.bitrate
            if self.data_bitrate:
                kwargs["data_bitrate"] = self.data_bitrate
        if self.fd:
            kwargs["fd"] = True
        try:
            return can.Bus(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as err:
            raise BusError(
                f"cannot open CAN interface {self.interface!r} channel {self.channel!r}: {err}"
            ) from err


def to_message(frame: Frame) -> can.Message:
    return can.Message(
        arbitration_id=frame.arbitration_id,
        data=frame.data,
        is_fd=frame.is_fd,
        is_remote_frame=frame.is_remote,
        is_extended_id=frame.is_extended_id,
        bitrate_switch=frame.is_fd,
        dlc=0 if frame.is_remote else len(frame.data),
    )


def to_frame(msg: can.Message) -> Frame:
    return Frame(
        arbitration_id=msg.arbitration_id,
        data=bytes(msg.data),
        is_fd=msg.is_fd,
        is_remote=msg.is_remote_frame,
        is_extended_id=msg.is_extended_id,
    )


@dataclass
class BusCounters:
    tx: int = 0
    rx: int = 0
    tx_errors: int = 0
    rx_errors: int = 0
    malformed: int = 0
    other: int = 0  # frames that complete no sample: other nodes, heartbeats, partial replies
    samples: int = 0
    late: int = 0  # replies that came after their cycle's timeout (still published)
    duplicates: int = 0  # replies not newer than one already handed on: copies, stale ones
    last_error: str = ""
    extra: dict[str, int] = field(default_factory=dict)


class ActuatorClient:
    """Sends an adapter's frames on a bus and turns what comes back into feedback."""

    def __init__(
        self,
        protocol: ActuatorProtocol,
        bus: can.BusABC,
        *,
        clock: Callable[[], float] = time.monotonic,
        decode: Callable[[Frame], Feedback | None] | None = None,
    ) -> None:
        """``decode`` replaces ``protocol.decode`` (a bus of several motors routes frames to
        the protocol of the motor they come from, ``canbus.multi``)."""
        self.protocol = protocol
        self.decode = decode or protocol.decode
        self.bus: can.BusABC | None = bus
        self.clock = clock
        self.counters = BusCounters()
        self.last_feedback: Feedback | None = None
        # bus time (time.time() base) of the frame that completed the last sample, when the
        # interface's timestamps are on that base (socketcan kernel stamps, virtual); else None
        self.last_rx_wall_s: float | None = None

    def send(self, frames: Iterable[Frame]) -> bool:
        """Send every frame; False if any failed (counted, never raised)."""
        ok = True
        bus = self.bus
        for frame in frames:
            if bus is None:
                return False
            try:
                bus.send(to_message(frame))
                self.counters.tx += 1
            except (can.CanError, OSError, ValueError) as err:
                self.counters.tx_errors += 1
                self.counters.last_error = f"send: {err}"
                ok = False
        return ok

    def receive(self, timeout_s: float) -> Feedback | None:
        """Read frames until one completes a sample, or ``timeout_s`` passes. The bus time of
        the completing frame is in :attr:`last_rx_wall_s`."""
        bus = self.bus
        if bus is None:
            return None
        deadline = self.clock() + max(0.0, timeout_s)
        while True:
            remaining = deadline - self.clock()
            try:
                msg = bus.recv(timeout=max(0.0, remaining))
            except (can.CanError, OSError, ValueError) as err:
                self.counters.rx_errors += 1
                self.counters.last_error = f"receive: {err}"
                return None
            if msg is None:
                return None
            if msg.is_error_frame:
                self.counters.rx_errors += 1
                continue
            self.counters.rx += 1
            try:
                feedback = self.decode(to_frame(msg))
            except MalformedFrameError as err:
                self.counters.malformed += 1
                self.counters.last_error = f"malformed frame 0x{msg.arbitration_id:x}: {err}"
                continue
            if feedback is None:
                self.counters.other += 1
                continue
            stamp = msg.timestamp
            self.counters.samples += 1
            self.last_feedback = feedback
            self.last_rx_wall_s = stamp if abs(stamp - time.time()) < EPOCH_TOLERANCE_S else None
            return feedback

    def drain(self) -> list[tuple[Feedback, float | None]]:
        """Read whatever is queued now: samples with their bus times (None: not epoch-based)."""
        queued: list[tuple[Feedback, float | None]] = []
        while self.bus is not None:
            feedback = self.receive(0.0)
            if feedback is None:
                break
            queued.append((feedback, self.last_rx_wall_s))
        return queued

    def close(self) -> None:
        """Shut the bus down; safe to call more than once."""
        bus, self.bus = self.bus, None
        if bus is not None:
            bus.shutdown()
