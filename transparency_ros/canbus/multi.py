"""Several actuators in one loop: one thread, one cycle per period for all motors, ROS-free.

A robot's motors sit on one or more CAN buses, one protocol per bus. Each cycle sends every
active motor its command (bus by bus, back to back), then collects the replies until every
motor has answered or ``reply_timeout_s`` has passed, and hands one :class:`RobotSample` with
the motors that answered to ``on_sample`` (the node publishes it as one /joint_states). Frames
are routed to a motor by the id they were sent with (``ActuatorProtocol.sender``), so motors
of the same protocol share a bus without a thread each.

Each motor has its own :class:`~transparency_ros.core.driver.DriverCore`: its own target,
command watchdog and reply watchdog. A tripped reply watchdog disables that motor at once;
with ``fault_policy = all`` (the default) every other motor is disabled with it, because the
joints of a robot hold each other up and one limp joint can swing the rest; ``motor`` keeps the
others running. :meth:`disable` disables all motors, and the node calls it on every exit path.

The wait for replies is ``reply_timeout_s`` per motor on the busiest bus (replies on one bus
come one after another), at most 0.9 period. Replies that come after their cycle's wait are
late: they update the motor's watchdog and last state (a slow motor is alive) but are not
published, since their cycle's message has gone.
The message's time is the mean bus time of its replies (``spread_s`` says how far apart they
were; on a 1 Mbit/s bus each classic frame takes ~0.13 ms, so twelve motors on one bus spread
over ~3 ms and cannot all answer within a 1 kHz cycle: put them on several buses).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import can

from transparency_ros.canbus.client import ActuatorClient
from transparency_ros.canbus.clock import WALL
from transparency_ros.canbus.loop import PeriodicLoop, command_at, reads_zeroed
from transparency_ros.canbus.protocol import ActuatorProtocol, Feedback, Frame
from transparency_ros.core.driver import DriverCore, DriverMode, ImpedanceCommand

FAULT_POLICIES = ("all", "motor")
POLL_SLICE_S = 100e-6  # longest wait on one bus while others owe replies


@dataclass
class Motor:
    """One actuator of the loop: its joint name, wire protocol, core and bus (index)."""

    name: str
    protocol: ActuatorProtocol
    core: DriverCore
    bus: int = 0
    last_feedback: Feedback | None = None
    samples: int = 0
    late: int = 0
    duplicates: int = 0
    superseded: int = 0  # replies to commands sent again fresh within their cycle


@dataclass(frozen=True)
class RobotSample:
    """One cycle's replies: motor indices (loop order) with their feedback."""

    stamp_s: float  # the loop's clock: mean bus time of the replies
    spread_s: float  # last minus first reply's bus time
    indices: tuple[int, ...]
    feedback: tuple[Feedback, ...]
    # the command each reply answers (None: that motor was not driven)
    commands: tuple[ImpedanceCommand | None, ...] = ()


class _Router:
    """Which motor of a bus a frame comes from: the protocol's sender id, looked up."""

    def __init__(self, motors: Sequence[tuple[int, ActuatorProtocol]]) -> None:
        self.by_id = {protocol.device_id: (index, protocol) for index, protocol in motors}
        if len(self.by_id) != len(motors):
            ids = [protocol.device_id for _, protocol in motors]
            raise ValueError(f"two motors on one bus answer with the same id: {ids}")
        self.sender = motors[0][1].sender
        self.last_index = -1

    def decode(self, frame: Frame) -> Feedback | None:
        entry = self.by_id.get(self.sender(frame))  # type: ignore[arg-type]
        if entry is None:
            return None
        feedback = entry[1].decode(frame)
        if feedback is not None:
            self.last_index = entry[0]
        return feedback


@dataclass
class _Collected:
    replies: dict[int, tuple[Feedback, float | None]] = field(default_factory=dict)
    # motor index -> frames sent it this cycle that ask a reply (default 1), replies taken
    expected: dict[int, int] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)

    def owes(self, index: int) -> bool:
        return self.counts.get(index, 0) < self.expected.get(index, 1)


class MultiControlLoop(PeriodicLoop):
    def __init__(
        self,
        buses: Sequence[can.BusABC],
        motors: Sequence[Motor],
        *,
        rate_hz: float,
        reply_timeout_s: float,
        fault_policy: str = "all",
        on_sample: Callable[[RobotSample], None] = lambda _s: None,
        on_fault: Callable[[str], None] = lambda _reason: None,
        on_error: Callable[[BaseException], None] = lambda _err: None,
        clock: Callable[[], float] = time.monotonic,
        stats_window: int = 5000,
    ) -> None:
        """``buses``: opened python-can buses; ``motors[i].bus`` indexes them. The wait for
        replies is ``reply_timeout_s`` per motor of the busiest bus, at most 0.9 period."""
        super().__init__(rate_hz, on_error, clock, stats_window, "robot_loop")
        if not motors:
            raise ValueError("no motors")
        if fault_policy not in FAULT_POLICIES:
            raise ValueError(f"fault_policy must be one of {FAULT_POLICIES}, got {fault_policy!r}")
        names = [m.name for m in motors]
        if len(set(names)) != len(names):
            raise ValueError(f"joint names must be unique, got {names}")
        self.motors = list(motors)
        self.fault_policy = fault_policy
        # replies on one bus come one after another: the wait grows with its motors
        per_bus = max(sum(m.bus == b for m in motors) for b in range(len(buses)))
        self.reply_timeout_s = min(reply_timeout_s * per_bus, 0.9 * self.period_s)
        self.on_sample, self.on_fault = on_sample, on_fault
        self.routers: list[_Router] = []
        self.clients: list[ActuatorClient] = []
        for b, bus in enumerate(buses):
            on_bus = [(i, m.protocol) for i, m in enumerate(motors) if m.bus == b]
            if not on_bus:
                raise ValueError(f"bus {b} has no motor")
            router = _Router(on_bus)
            self.routers.append(router)
            self.clients.append(
                ActuatorClient(on_bus[0][1], bus, clock=clock, decode=router.decode)
            )
        if any(not 0 <= m.bus < len(self.clients) for m in motors):
            raise ValueError("a motor's bus index is out of range")
        self._last_stamp_s = float("-inf")

    # ----------------------------------------------------------------- I/O

    def _send(self, index: int, frames: list[Frame]) -> None:
        self.clients[self.motors[index].bus].send(frames)

    def _collect(self, wanted: set[int], deadline_s: float, since_wall_s: float,
                 answers: Callable[[int, Feedback], bool] | None = None,
                 expected: dict[int, int] | None = None) -> _Collected:  # fmt: skip
        """Read replies until every motor in ``wanted`` answered or ``deadline_s``. Replies
        stamped before ``since_wall_s``, or refused by ``answers`` (motor index, reply), answer
        older requests: counted late, state kept. ``expected``: frames sent a motor this cycle
        (default 1; more when commands went again fresh): it answers each, in order, and the
        last is taken, the earlier counted superseded.
        With several buses, the wait blocks on a bus that still owes replies, in short slices
        (python-can has no portable wait on several buses), and the others are read as they are."""
        got = _Collected(expected=expected or {})
        while True:
            owing = {self.motors[i].bus for i in wanted if got.owes(i)}
            remaining = deadline_s - self.clock()
            if not owing or remaining <= 0:
                break
            for b, (client, router) in enumerate(zip(self.clients, self.routers, strict=True)):
                if b not in owing:
                    continue
                wait = remaining if len(owing) == 1 else min(remaining, POLL_SLICE_S)
                feedback = client.receive(wait)
                while feedback is not None:
                    index = router.last_index
                    old = answers is not None and not answers(index, feedback)
                    rx = -math.inf if old else client.last_rx_wall_s
                    self._take(index, feedback, rx, since_wall_s, got)
                    feedback = client.receive(0.0)
                remaining = deadline_s - self.clock()
                if remaining <= 0:
                    break
        return got

    def _take(
        self, index: int, feedback: Feedback, rx: float | None, since_wall_s: float, got: _Collected
    ) -> None:
        motor = self.motors[index]
        motor.last_feedback = feedback
        motor.core.on_feedback(feedback.position_rad, self.clock())
        if rx is not None and rx < since_wall_s:
            motor.late += 1
        elif index in got.replies and not got.owes(index):
            motor.duplicates += 1
        else:
            if index in got.replies:
                motor.superseded += 1  # the answer to a stale send: the fresh one's follows
            got.replies[index] = (feedback, rx)
            got.counts[index] = got.counts.get(index, 0) + 1

    def _drain(self, since_wall_s: float) -> None:
        for client, router in zip(self.clients, self.routers, strict=True):
            for feedback, rx in client.drain():
                motor = self.motors[router.last_index]
                motor.last_feedback = feedback
                motor.core.on_feedback(feedback.position_rad, self.clock())
                if rx is None or rx < since_wall_s:
                    motor.late += 1

    # ----------------------------------------------------------------- control

    def enable(self, timeout_s: float = 0.2) -> list[str]:
        """Enable every motor and hold where each is. Returns the motors that did not answer
        (they are put in FAULT; the caller should then :meth:`disable` all)."""
        with self.lock:
            since = WALL(self.clock())
            for i, motor in enumerate(self.motors):
                motor.core.clear_fault()
                self._send(i, motor.protocol.enable_frames())
            got = self._collect(set(range(len(self.motors))), self.clock() + timeout_s, since)
            missing = []
            for i, motor in enumerate(self.motors):
                if i in got.replies:
                    motor.core.activate(got.replies[i][0].position_rad)
                else:
                    motor.core.fault("no reply to enable")
                    missing.append(motor.name)
            return missing

    def disable(self, timeout_s: float = 0.05) -> list[str]:
        """Zero torque and motor off for every motor. Safe at any time, repeatedly. Waits up
        to ``timeout_s`` for a reply from each motor sent the frames (they end with a request
        for its state, answered after the device took the disable: frames are taken in order),
        then takes what else has come. Returns the motors that did not answer: whether they
        took the disable is unknown (a busy computer, a device off the bus)."""
        with self.lock:
            since = WALL(self.clock())
            sent = set()
            for i, motor in enumerate(self.motors):
                motor.core.deactivate()
                if self.clients[motor.bus].bus is not None:
                    self._send(i, motor.protocol.disable_frames())
                    sent.add(i)
            got = self._collect(sent, self.clock() + timeout_s, since)
            self._drain(float("inf"))
            return [self.motors[i].name for i in sorted(sent - got.replies.keys())]

    def set_zero(self, timeout_s: float = 0.1, quiet_s: float = 0.005) -> list[str]:
        """Make every motor's current position read zero, then hold there. A motor's answer is
        its last reply in the new frame (``loop.reads_zeroed``: replies to older commands come
        first and read the old one) within a quiet window. Returns the motors without one:
        they are faulted and disabled (whether their frame moved is unknown), and with
        ``fault_policy`` all, every other motor with them."""
        with self.lock:
            self._drain(float("inf"))
            since = WALL(self.clock())
            before = [motor.last_feedback for motor in self.motors]
            for i, motor in enumerate(self.motors):
                self._send(i, motor.protocol.zero_frames(before[i]))

            def zeroed(index: int, feedback: Feedback) -> bool:
                return reads_zeroed(feedback.position_rad, before[index])

            wanted = set(range(len(self.motors)))
            got = self._collect(wanted, self.clock() + timeout_s, since, zeroed)
            while True:  # keep the newest of each until the bus is quiet
                more = self._collect(wanted, self.clock() + quiet_s, since, zeroed)
                if not more.replies:
                    break
                got.replies.update(more.replies)
            for i, motor in enumerate(self.motors):
                if i in got.replies and motor.core.mode is DriverMode.ACTIVE:
                    motor.core.activate(got.replies[i][0].position_rad)
            silent = [i for i in wanted - got.replies.keys()
                      if self.motors[i].core.mode is DriverMode.ACTIVE]  # fmt: skip
            reason = f"set_zero: no reply in the new frame within {timeout_s * 1e3:.0f} ms"
            self._trip(silent, reason)
            missing = [m.name for i, m in enumerate(self.motors) if i not in got.replies]
        if silent:
            self.on_fault(f"{', '.join(self.motors[i].name for i in silent)}: {reason}")
        return missing

    def _trip(self, indices: list[int], reason: str | None = None) -> None:
        """Fault (for ``reason``; None: they faulted themselves) and disable the motors
        ``indices``, and with ``fault_policy`` all, every motor still active with them."""
        if not indices:
            return
        names = ", ".join(self.motors[i].name for i in indices)
        others = [i for i, m in enumerate(self.motors)
                  if i not in indices and m.core.mode is DriverMode.ACTIVE]  # fmt: skip
        for i in indices + (others if self.fault_policy == "all" else []):
            motor = self.motors[i]
            if i not in indices:
                motor.core.fault(f"disabled with {names} (fault_policy all)")
            elif reason is not None:
                motor.core.fault(reason)
            self._send(i, motor.protocol.disable_frames())

    # ----------------------------------------------------------------- the loop

    def cycle(self) -> None:
        """One cycle for all motors (the thread runs it every period; tests may call it)."""
        faults: list[str] = []
        with self.lock:
            self._drain(WALL(self.clock()))
            first_s = self.clock()
            sent = [self._send_fresh(i) for i in range(len(self.motors))]
            commands = [command for command, _, _ in sent]
            driven = {i for i, command in enumerate(commands) if command is not None}
            sent_s = sent[-1][1]  # the last command's time: the wait runs from it
            wanted = set(range(len(self.motors)))
            expected = {i: sends for i, (_, _, sends) in enumerate(sent)}
            got = self._collect(wanted, sent_s + self.reply_timeout_s, WALL(first_s),
                                expected=expected)  # fmt: skip
            tripped = [i for i in sorted(driven - got.replies.keys())
                       if self.motors[i].core.on_missed_reply(
                           sent_s, self.min_unanswered(self.motors[i].core))]  # fmt: skip
            # a device that stopped driving on its own (its reply says so) stops its motor too
            for i, (feedback, _rx) in sorted(got.replies.items()):
                core = self.motors[i].core
                if feedback.device_fault and core.mode is DriverMode.ACTIVE:
                    core.fault(f"the device reports: {feedback.device_fault}")
                    tripped.append(i)
            faults = [f"{self.motors[i].name}: {self.motors[i].core.status.fault_reason}"
                      for i in tripped]  # fmt: skip
            self._trip(tripped)
            sample = self._sample(got, sent)
        if sample is not None:
            self.on_sample(sample)
        for reason in faults:
            self.on_fault(reason)

    def _send_fresh(self, index: int) -> tuple[ImpedanceCommand | None, float, int]:
        """Motor ``index``'s command sent (:meth:`PeriodicLoop.send_fresh`: each motor's own
        send is timed, so a robot's many sends in a row are not taken for a stall), or a poll
        when it is not driven (faulted, disabled: still published)."""
        motor = self.motors[index]

        def send(command: ImpedanceCommand | None) -> None:
            protocol = motor.protocol
            self._send(index, protocol.query_frames() if command is None
                       else protocol.command_frames(command, motor.last_feedback))  # fmt: skip

        return self.send_fresh(motor.core.command, send)

    def _sample(
        self, got: _Collected, sent: list[tuple[ImpedanceCommand | None, float, int]]
    ) -> RobotSample | None:
        if not got.replies:
            return None
        indices = tuple(sorted(got.replies))
        times = []
        wall_offset_s = WALL.offset_s()  # (once per cycle, not per motor)
        for i in indices:
            rx, sent_s = got.replies[i][1], sent[i][1]
            # its bus time, at most a period after its command (an answer to a stale send whose
            # fresh one's did not come: its own time, before the fresh command's)
            latency = 0.0 if rx is None else min(rx - sent_s - wall_offset_s, self.period_s)
            times.append(sent_s + latency)
            self.motors[i].samples += 1
        stamp = sum(times) / len(times)
        if stamp <= self._last_stamp_s:  # never publish time going backwards
            return None
        self._last_stamp_s = stamp
        return RobotSample(
            stamp, max(times) - min(times), indices, tuple(got.replies[i][0] for i in indices),
            tuple(command_at(sent[i][0], sent[i][1], stamp) for i in indices),
        )  # fmt: skip

    def emergency_stop(self, reason: str) -> None:
        for i, motor in enumerate(self.motors):
            motor.core.fault(reason)
            if self.clients[motor.bus].bus is not None:
                self._send(i, motor.protocol.disable_frames())

    def close(self) -> None:
        """Shut the buses down (after :meth:`disable`); safe to call more than once."""
        for client in self.clients:
            client.close()
