"""Several simulated actuators on virtual buses, as the motors of a robot share its buses:
:class:`SimulatedBus` serves the devices of one bus from one thread, :class:`SimulatedBuses`
several buses from one thread. Each device is a :mod:`~transparency_ros.canbus.sim_device`
personality with its own physics, answering as a lone :class:`~transparency_ros.canbus.
sim_device.SimulatedActuator` does.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import Counter
from collections.abc import Callable

import can

from transparency_ros.canbus.client import BusSettings, to_frame, to_message
from transparency_ros.canbus.clock import WALL
from transparency_ros.canbus.errors import CanProtocolError
from transparency_ros.canbus.protocol import Frame
from transparency_ros.canbus.sim_device import Personality
from transparency_ros.core.actuator_physics import ActuatorPhysics


class SimulatedBus:
    """Several simulated actuators on one virtual bus, served by one thread, as the motors of a
    robot share a bus. Each frame goes to the device it is addressed to
    (:meth:`Personality.addressed`), which first advances its own physics to the frame's bus
    time and then answers, exactly as a lone :class:`SimulatedActuator` does; devices no frame
    reaches are advanced on idle ticks. One thread instead of one per device keeps a 12-motor
    robot's simulation from taking the interpreter away from the driver's loop.

    :meth:`silence` cuts one device's replies (a broken cable to one motor)."""

    def __init__(
        self,
        devices: list[tuple[ActuatorPhysics, Personality]],
        bus_settings: BusSettings | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        idle_tick_s: float = 0.002,
    ) -> None:
        if not devices:
            raise CanProtocolError("a simulated bus needs at least one device")
        self.settings = bus_settings or BusSettings()
        if self.settings.interface != "virtual":
            raise CanProtocolError("the simulated actuators only attach to a 'virtual' bus")
        self.physics = [physics for physics, _ in devices]
        self.personalities = [personality for _, personality in devices]
        self.clock = clock
        self.idle_tick_s = idle_tick_s
        self.lock = threading.Lock()
        self._silent: set[int] = set()
        self._last_s: list[float | None] = [None] * len(devices)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._bus: can.BusABC | None = None
        self.replies_sent = 0
        self.frames_received = 0
        self._next_idle = 0.0

    def open(self) -> SimulatedBus:
        """Attach to the bus without a thread of its own (:class:`SimulatedBuses` serves it)."""
        if self._bus is None:
            self._bus = self.settings.open(preserve_timestamps=True)
            now = self.clock()
            self._last_s = [now] * len(self.physics)
            self._next_idle = now + self.idle_tick_s
        return self

    def start(self) -> SimulatedBus:
        if self._thread is not None:
            return self
        self.open()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="simulated_bus", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Switch the devices off; frames already on the wire to them are taken first."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        bus, self._bus = self._bus, None
        if bus is not None:
            while True:
                try:
                    msg = bus.recv(timeout=0.0)
                except (can.CanError, OSError):
                    break
                if msg is None:
                    break
                self._handle(to_frame(msg), self.clock())
            bus.shutdown()

    def __enter__(self) -> SimulatedBus:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def silence(self, index: int, silent: bool = True) -> None:
        """Stop (or resume) device ``index``'s replies."""
        with self.lock:
            (self._silent.add if silent else self._silent.discard)(index)

    def events(self, index: int) -> Counter[str]:
        with self.lock:
            return Counter(self.personalities[index].events)

    def enabled(self) -> list[bool]:
        """Which devices would drive their motor now."""
        with self.lock:
            return [p.is_enabled() for p in self.personalities]

    def _advance(self, index: int, now: float) -> None:
        last = self._last_s[index]
        last = now if last is None else last
        physics, device = self.physics[index], self.personalities[index]
        if now > last and not device.time_varying:
            physics.advance(now - last, device.drive)
        elif now > last:
            steps = math.ceil((now - last) / physics.max_step_s)
            dt = (now - last) / steps
            for i in range(steps):
                physics.advance(dt, device.drive_at(last + (i + 0.5) * dt))
        self._last_s[index] = max(now, last)

    def _handle(self, frame: Frame, now: float) -> list[tuple[int, Frame]]:
        out: list[tuple[int, Frame]] = []
        with self.lock:
            for index, device in enumerate(self.personalities):
                if device.addressed(frame):
                    self._advance(index, now)
                    out += [(index, f) for f in device.handle(frame, self.physics[index], now)]
        return out

    def _run(self) -> None:
        while not self._stop.is_set():
            self.serve(self.idle_tick_s)

    def serve(self, timeout_s: float) -> bool:
        """Take one frame (waiting up to ``timeout_s``), answer it, run due idle ticks. True if
        a frame was taken. :class:`SimulatedBuses` calls it to run several buses in one thread."""
        bus = self._bus
        if bus is None:
            return False
        try:
            msg = bus.recv(timeout=max(0.0, min(timeout_s, self._next_idle - self.clock())))
        except (can.CanError, OSError):
            return False
        now = self.clock()
        out: list[tuple[int, Frame]] = []
        if msg is not None:
            self.frames_received += 1
            # act at the frame's bus time (the thread may have been late to read it)
            at = now - max(0.0, WALL(now) - msg.timestamp)
            out = self._handle(to_frame(msg), at)
        if now >= self._next_idle:
            self._next_idle = now + self.idle_tick_s
            with self.lock:
                for index, device in enumerate(self.personalities):
                    self._advance(index, now)
                    out += [(index, f) for f in device.tick(self.physics[index], now)]
        sent_at = WALL(now)
        for index, frame in out:
            if index in self._silent:
                continue
            message = to_message(frame)
            message.timestamp = sent_at
            with contextlib.suppress(can.CanError, OSError):
                bus.send(message)
                self.replies_sent += 1
        return msg is not None


class SimulatedBuses:
    """Several :class:`SimulatedBus` served by one thread (a robot wired to several buses):
    one thread per bus would make each wait for the interpreter behind the others, and the
    driver's loop behind all of them. Each bus is polled in turn; when none has a frame the
    thread sleeps ``poll_s``."""

    def __init__(self, buses: list[SimulatedBus], poll_s: float = 100e-6) -> None:
        self.buses = buses
        self.poll_s = poll_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> SimulatedBuses:
        if self._thread is None:
            for sim in self.buses:
                sim.open()
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="simulated_buses", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        if len(self.buses) == 1:  # one bus: block on it
            while not self._stop.is_set():
                self.buses[0].serve(self.buses[0].idle_tick_s)
            return
        while not self._stop.is_set():
            busy = False
            for sim in self.buses:
                while sim.serve(0.0):
                    busy = True
            if not busy:
                time.sleep(self.poll_s)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for sim in self.buses:
            sim.stop()
