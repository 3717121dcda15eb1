"""The driver's hardware loop: one thread, one cycle per period, ROS-free.

Each cycle: ask :class:`DriverCore` for a command, send it, wait up to ``reply_timeout_s`` for
the reply, hand the sample to ``on_sample`` (the ROS node publishes it), count a missed reply
otherwise. A reply that comes after its cycle's timeout is still a true measurement: it is
handed on (with its own time) in the next cycle and counted as late, never taken for the answer
to a newer request.

A sample's time is when the reply was on the bus (the interface's receive timestamp, e.g. the
socketcan kernel stamp), not when this thread got to read it: a device answers within about
0.1 ms, but reading can wait for the host's scheduler for milliseconds, and at 1 rev/s each
millisecond is 6 mrad of apparent position error. Interfaces without epoch timestamps fall back
to the time the request was sent (late replies from them are dropped: their time is unknown).

A tripped reply watchdog (``core.driver``: silent for a time, over enough requests) sends the
protocol's disable frames at once. A motor that is not driven (faulted, or disabled while the loop
runs) is still polled with the protocol's query frames, which do not drive it, and its replies
are still handed on: what the bus reports stays visible. Deadlines are absolute (no drift); a
cycle that overruns by a whole period resynchronises and is counted.

A command is computed for the instant its cycle starts and sent at once; if the send returns
over half a period later (the host stalled in between), it is computed and sent again for now
(:meth:`PeriodicLoop.is_stale`, at most three frames a cycle): a device takes the setpoint it
receives for the present, and a moteus ramps on from it, so a stale one pulls a moving joint
back by theta_d' times the stall (0.1 rad after 17 ms at 1 rev/s). The reply the loop keeps is
the last of the cycle's; a reply to an earlier send keeps its own time.

The loop also measures itself: achieved rate and cycle jitter (|actual period - nominal|).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from transparency_ros.canbus.client import ActuatorClient
from transparency_ros.canbus.clock import WALL
from transparency_ros.canbus.protocol import Feedback
from transparency_ros.core.driver import DriverCore, DriverMode, ImpedanceCommand
from transparency_ros.core.histogram import DurationHistogram

# a reply, its time, and the command of the request it answers at that time (None: the motor
# was not driven; a late reply is taken to answer the previous cycle's request)
_Answer = tuple[Feedback, float, ImpedanceCommand | None]


# a command whose send returned over this share of a period after the time it was computed for
# is sent again, fresh (PeriodicLoop.is_stale); at most this many frames per motor and cycle
STALE_COMMAND_SHARE = 0.5
MAX_COMMAND_SENDS = 3

# a zero's answer and an older reply whose readings differ by less than this need no telling
# apart: holding either moves the motor by less
ZERO_SAME_FRAME_RAD = 0.01


def reads_zeroed(position_rad: float, before: Feedback | None) -> bool:
    """Whether a reply after a zero request reads in the new frame: nearer zero than the
    position before the request. A reply to an older request, still in flight on a busy host
    (or from a device thread that stalled), reads the old frame; holding it as the new zero
    would move the motor by the old reading (CI: three motors held at 0.5 rad went back there)."""
    if before is None or abs(before.position_rad) < ZERO_SAME_FRAME_RAD:
        return True
    return abs(position_rad) < abs(position_rad - before.position_rad)


def zero_answer(receive: Callable[[float], Feedback | None], before: Feedback | None,
                clock: Callable[[], float], timeout_s: float, quiet_s: float
                ) -> Feedback | None:  # fmt: skip
    """The last reply read in the new frame (:func:`reads_zeroed`) before the bus has been quiet
    for ``quiet_s`` after it, waiting up to ``timeout_s`` for the first; None if none came."""
    answer = None
    deadline = clock() + timeout_s
    while True:
        wait = quiet_s if answer is not None else deadline - clock()
        if wait <= 0:
            return None
        feedback = receive(wait)
        if feedback is None:
            return answer
        if reads_zeroed(feedback.position_rad, before):
            answer = feedback


def command_at(command: ImpedanceCommand | None, sent_s: float, at_s: float
               ) -> ImpedanceCommand | None:  # fmt: skip
    """A command sent at ``sent_s`` as it stands at ``at_s``: its position advanced by its
    velocity (a streamed trajectory's theta_d at the instant a reply measured the joint, as
    the driver itself advances it between commands and a moteus does in the device)."""
    if command is None or command.velocity_rad_s == 0.0 or command.kp_nm_per_rad == 0.0:
        return command
    return replace(
        command, position_rad=command.position_rad + command.velocity_rad_s * (at_s - sent_s)
    )


@dataclass(frozen=True)
class LoopStats:
    cycles: int
    overruns: int
    rate_hz: float  # achieved, over the stats window
    jitter_p50_s: float
    jitter_p99_s: float
    jitter_max_s: float
    cpu_p50_s: float = 0.0  # the loop thread's CPU time per cycle (its own cost, not waits)
    cpu_p99_s: float = 0.0


class PeriodicLoop:
    """A thread running :meth:`cycle` every period on absolute deadlines, measuring itself.
    An exception out of a cycle stops the loop after :meth:`emergency_stop` (motors safe)."""

    def __init__(
        self,
        rate_hz: float,
        on_error: Callable[[BaseException], None],
        clock: Callable[[], float],
        stats_window: int,
        name: str,
    ) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate must be > 0 Hz, got {rate_hz}")
        self.period_s = 1.0 / rate_hz
        self.on_error = on_error
        self.clock = clock
        self.name = name
        self.lock = threading.RLock()  # guards the cores and the buses between loop and callers
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._starts: deque[float] = deque(maxlen=stats_window)
        self._cpu: deque[int] = deque(maxlen=stats_window)
        self.cycles = 0
        self.overruns = 0
        self.lateness = DurationHistogram()  # cycle start - its deadline (the host's stalls)
        self.resent_commands = 0  # commands sent again because the first left stale

    def is_stale(self, computed_s: float, left_s: float, sends: int) -> bool:
        """Whether a command computed for ``computed_s`` whose send returned at ``left_s`` left
        stale and is to be sent again (counted), fresh: more than STALE_COMMAND_SHARE of a
        period late, at most MAX_COMMAND_SENDS frames per cycle. A host stalled between
        computing a command and sending it would otherwise hand the device a setpoint that old:
        a moteus (and its simulation) starts its position ramp from the setpoint it receives, so
        17 ms of stall braked a 1 rev/s sweep by 0.1 rad, the error then rose by 10 mrad for tens
        of ms and the feel-cage cell measured e_s that much too high (and missed the ball)."""
        if left_s - computed_s <= STALE_COMMAND_SHARE * self.period_s or sends >= MAX_COMMAND_SENDS:
            return False
        self.resent_commands += 1
        return True

    def send_fresh(
        self,
        command_at: Callable[[float], ImpedanceCommand | None],
        send: Callable[[ImpedanceCommand | None], None],
    ) -> tuple[ImpedanceCommand | None, float, int]:
        """Compute a motor's command for now and send it (None: a poll, nothing to go
        stale), again while it left stale (:meth:`is_stale`): (the command sent last, the time
        it was computed for, frames sent)."""
        now_s = self.clock()
        sends = 0
        while True:
            command = command_at(now_s)
            send(command)
            sends += 1
            left_s = self.clock()
            if command is None or not self.is_stale(now_s, left_s, sends):
                return command, now_s, sends
            now_s = left_s

    def min_unanswered(self, core: DriverCore) -> int:
        """Requests a silent motor must have left unanswered before its watchdog trips: half of
        what this loop sends in ``reply_silence_s`` (at least 3), so that a stall of this host,
        during which nothing was asked, is not taken for a silent motor."""
        return max(3, int(0.5 * core.settings.reply_silence_s / self.period_s))

    def cycle(self) -> None:
        raise NotImplementedError

    def emergency_stop(self, reason: str) -> None:
        """Leave every motor safe after a failure of the loop itself."""
        raise NotImplementedError

    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        deadline = self.clock()
        try:
            while not self._stop.is_set():
                start = self.clock()
                self.lateness.add(max(start - deadline, 0.0))
                self._starts.append(start)
                self.cycles += 1
                cpu = time.thread_time_ns()
                self.cycle()
                self._cpu.append(time.thread_time_ns() - cpu)
                deadline += self.period_s
                remaining = deadline - self.clock()
                if remaining < -self.period_s:
                    self.overruns += 1
                    deadline = self.clock()
                elif remaining > 0:
                    self._stop.wait(remaining)
        except BaseException as err:  # noqa: BLE001 - any failure must leave the motors safe
            with self.lock:
                self.emergency_stop(f"loop error: {err!r}")
            self.on_error(err)

    def stats(self) -> LoopStats:
        starts = np.array(self._starts)
        if starts.size < 3:
            return LoopStats(self.cycles, self.overruns, 0.0, 0.0, 0.0, 0.0)
        periods = np.diff(starts)
        jitter = np.abs(periods - self.period_s)
        cpu = np.array(self._cpu, dtype=float) * 1e-9
        return LoopStats(
            cycles=self.cycles,
            overruns=self.overruns,
            rate_hz=float(periods.size / (starts[-1] - starts[0])),
            jitter_p50_s=float(np.percentile(jitter, 50)),
            jitter_p99_s=float(np.percentile(jitter, 99)),
            jitter_max_s=float(jitter.max()),
            cpu_p50_s=float(np.percentile(cpu, 50)) if cpu.size else 0.0,
            cpu_p99_s=float(np.percentile(cpu, 99)) if cpu.size else 0.0,
        )

    def reset_stats(self) -> None:
        self._starts.clear()
        self._cpu.clear()


class ControlLoop(PeriodicLoop):
    """One actuator's loop (``canbus.multi.MultiControlLoop`` drives several)."""

    def __init__(
        self,
        client: ActuatorClient,
        core: DriverCore,
        *,
        rate_hz: float,
        reply_timeout_s: float,
        # (sample, its time, the command it answers: None when the motor was not driven)
        on_sample: Callable[[Feedback, float, ImpedanceCommand | None], None] = (
            lambda _fb, _t, _c: None
        ),
        on_fault: Callable[[str], None] = lambda _reason: None,
        on_error: Callable[[BaseException], None] = lambda _err: None,
        clock: Callable[[], float] = time.monotonic,
        stats_window: int = 5000,
    ) -> None:
        super().__init__(rate_hz, on_error, clock, stats_window, "actuator_loop")
        self.client = client
        self.core = core
        self.reply_timeout_s = min(reply_timeout_s, 0.9 * self.period_s)
        self.on_sample, self.on_fault = on_sample, on_fault
        self._last_sample_s = -math.inf
        self._last_rx_wall_s = -math.inf  # bus time of the newest reply handed on
        self.superseded_replies = 0  # replies to commands sent again fresh (is_stale)
        # the last cycle's command and when it was sent (the late replies' request)
        self._previous: tuple[ImpedanceCommand | None, float] = (None, 0.0)

    # ----------------------------------------------------------------- control

    def enable(self, timeout_s: float = 0.2) -> Feedback | None:
        """Enable the motor and activate the core at the position it reports (None: no reply)."""
        with self.lock:
            self.core.clear_fault()
            self.client.send(self.client.protocol.enable_frames())
            feedback = self.client.receive(timeout_s)
            if feedback is None:
                self.core.fault("no reply to enable")
                return None
            self.core.on_feedback(feedback.position_rad)
            self.core.activate(feedback.position_rad)
            return feedback

    def disable(self, timeout_s: float = 0.05) -> bool:
        """Zero torque and motor off. Safe to call at any time, from any thread, repeatedly.
        Whether the motor answered within ``timeout_s`` (the frames end with a request for its
        state); False: whether it took the disable is unknown, or no bus."""
        with self.lock:
            self.core.deactivate()
            if self.client.bus is None:
                return False
            self.client.drain()  # (replies to earlier requests: not an answer to this one)
            self.client.send(self.client.protocol.disable_frames())
            return self.client.receive(timeout_s) is not None

    def set_zero(self, timeout_s: float = 0.1, quiet_s: float = 0.005) -> bool:
        """Make the current position read zero, then hold there.

        Replies still in flight from earlier commands report the old frame of reference, so
        queued frames are dropped first, a reply counts as the answer only if it reads in the
        new frame (:func:`reads_zeroed`), and the *last* such reply of a short quiet window is
        used. Without one within ``timeout_s`` the motor is faulted and disabled (whether its
        frame moved is unknown: holding either reading could move it by the old position) and
        False is returned.
        """
        with self.lock:
            self.client.drain()
            before = self.client.last_feedback
            self.client.send(self.client.protocol.zero_frames(before))
            answer = zero_answer(self.client.receive, before, self.clock, timeout_s, quiet_s)
            if answer is not None:
                self.core.on_feedback(answer.position_rad)
                if self.core.mode is DriverMode.ACTIVE:
                    self.core.activate(answer.position_rad)  # hold the new zero
                return True
            if self.core.mode is not DriverMode.ACTIVE:
                return False
            reason = f"set_zero: no reply in the new frame within {timeout_s * 1e3:.0f} ms"
            self.emergency_stop(reason)
        self.on_fault(reason)
        return False

    # ----------------------------------------------------------------- the loop

    def _late(self, feedback: Feedback, rx_wall_s: float | None, ref_s: float, ref_wall_s: float,
              samples: list[_Answer]) -> None:  # fmt: skip
        """A reply that missed its cycle: hand it on at its bus time (dropped when unknown).
        One whose bus time is not after the newest handed on is a copy (a device repeating
        itself, a reply storm) or stale: counted as a duplicate and dropped."""
        if rx_wall_s is not None and rx_wall_s <= self._last_rx_wall_s:
            self.client.counters.duplicates += 1
            return
        self.client.counters.late += 1
        if rx_wall_s is not None and abs(rx_wall_s - ref_wall_s) < 1.0:
            at_s = ref_s + (rx_wall_s - ref_wall_s)
            samples.append((feedback, at_s, command_at(*self._previous, at_s)))
            self._last_rx_wall_s = rx_wall_s
            self.core.on_feedback(feedback.position_rad, ref_s)

    def cycle(self) -> None:
        """One cycle; the loop thread runs it every period (tests may call it directly)."""
        samples: list[_Answer] = []  # (sample, its time, its command) in time order
        reason = ""
        with self.lock:
            ref_s = self.clock()
            ref_wall_s = WALL(ref_s)
            for queued, queued_rx in self.client.drain():
                self._late(queued, queued_rx, ref_s, ref_wall_s, samples)
            first_wall_s = WALL(self.clock())
            command, sent_s, sends = self.send_fresh(self.core.command, self._send)
            sent_wall_s = WALL(sent_s)

            def late(reply: Feedback, rx_wall_s: float) -> None:  # an older request's reply
                self._late(reply, rx_wall_s, ref_s, ref_wall_s, samples)

            feedback, rx = self._answer(sent_s + self.reply_timeout_s, first_wall_s, sends, late)
            if feedback is not None:
                # (negative for the answer to a stale send, measured before the fresh one left:
                # its own time, with theta_d of the same trajectory then)
                latency = 0.0 if rx is None else min(rx - sent_wall_s, self.period_s)
                samples.append(
                    (feedback, sent_s + latency, command_at(command, sent_s, sent_s + latency))
                )
                if rx is not None:
                    self._last_rx_wall_s = max(self._last_rx_wall_s, rx)
                self.core.on_feedback(feedback.position_rad, sent_s)
                if feedback.device_fault and self.core.mode is DriverMode.ACTIVE:
                    # the device stopped driving on its own: the driver stops too (disabled,
                    # FAULT until re-enabled), not commanding a motor that does not follow
                    reason = f"the device reports: {feedback.device_fault}"
                    self.emergency_stop(reason)
            elif command is not None and self.core.on_missed_reply(  # (a motor not driven
                sent_s,
                self.min_unanswered(self.core),  # has no watchdog: nothing to disable)
            ):
                self.client.send(self.client.protocol.disable_frames())
                reason = self.core.status.fault_reason
            self._previous = (command, sent_s)
        for sample, at_s, applied in samples:
            if at_s <= self._last_sample_s:  # never publish time going backwards
                self.client.counters.late += 1
                continue
            self._last_sample_s = at_s
            self.on_sample(sample, at_s, applied)
        if reason:
            self.on_fault(reason)

    def _answer(
        self,
        deadline_s: float,
        first_wall_s: float,
        sends: int,
        late: Callable[[Feedback, float], None],
    ) -> tuple[Feedback | None, float | None]:
        """This cycle's reply and its bus time, waiting until ``deadline_s``: the last of up to
        ``sends`` replies stamped from the first send on (with a command sent again fresh, the
        earlier ones answer the stale sends: counted superseded). Replies stamped before it
        answer older requests: to ``late``."""
        answer: tuple[Feedback | None, float | None] = (None, None)
        answered = 0
        while answered < sends:
            reply = self.client.receive(deadline_s - self.clock())
            if reply is None:
                break
            rx = self.client.last_rx_wall_s
            if rx is not None and rx < first_wall_s:
                late(reply, rx)
                continue
            answer, answered = (reply, rx), answered + 1
        self.superseded_replies += max(0, answered - 1)
        return answer

    def _send(self, command: ImpedanceCommand | None) -> None:
        """The command's frames, or a poll when the motor is not driven."""
        protocol = self.client.protocol
        self.client.send(
            protocol.query_frames()
            if command is None
            else protocol.command_frames(command, self.client.last_feedback)
        )

    def emergency_stop(self, reason: str) -> None:
        self.core.fault(reason)
        if self.client.bus is not None:
            self.client.send(self.client.protocol.disable_frames())
