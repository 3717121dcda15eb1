"""Client, control loop and simulated device on a python-can virtual bus, for each protocol."""

from __future__ import annotations

import itertools
import re
import time
from collections.abc import Callable, Iterator

import can
import pytest

from transparency_ros.canbus.client import ActuatorClient, BusSettings, to_message
from transparency_ros.canbus.errors import BusError
from transparency_ros.canbus.loop import ControlLoop, reads_zeroed
from transparency_ros.canbus.protocol import (
    ActuatorProtocol,
    Feedback,
    MitProtocol,
    MoteusProtocol,
    ODriveProtocol,
)
from transparency_ros.canbus.sim_device import (
    MitDevice,
    MoteusDevice,
    ODriveDevice,
    Personality,
    SimulatedActuator,
)
from transparency_ros.core.actuator_physics import ActuatorPhysics, ImpedanceLaw, PhysicsParams
from transparency_ros.core.config import get_actuator
from transparency_ros.core.driver import (
    DriverCore,
    DriverMode,
    DriverSettings,
    ImpedanceCommand,
    JointTarget,
)

_channels = itertools.count()
RIG_MOTEUS_WATCHDOG_S = 10.0
EXIT_EVENT = {"mit": "exit", "odrive": "axis_state_idle", "moteus": "mode_stopped"}
COMMAND_EVENT = {"mit": "command", "odrive": "set_input_torque", "moteus": "mode_position"}


DEFAULT_IDS = {"mit": 1, "odrive": 5, "moteus": 2}


def make(name: str, motor_id: int | None = None) -> tuple[ActuatorProtocol, Personality]:
    """A protocol and its simulated device (``motor_id``: the protocol's default here)."""
    i = DEFAULT_IDS[name] if motor_id is None else motor_id
    if name == "mit":
        return MitProtocol(i), MitDevice(i)
    if name == "odrive":
        return ODriveProtocol(i), ODriveDevice(i)
    # (the device's own watchdog at 10 s, the most it takes, not 0.1: these rigs are not about
    # it, and a stall of this process under a loaded suite would latch it;
    # test_a_device_that_stops_... is about it)
    return MoteusProtocol(i, watchdog_timeout_s=RIG_MOTEUS_WATCHDOG_S), MoteusDevice(i)


def open_loop(
    protocol: ActuatorProtocol,
    personality: Personality,
    *,
    silence_s: float = 0.1,
    rate_hz: float = 500.0,
    bus: Callable[[BusSettings], can.BusABC] = BusSettings.open,
) -> tuple[ControlLoop, SimulatedActuator, list[str]]:
    """A control loop and a simulated device (started) on a channel of their own: (loop,
    device, the loop's fault reasons as they come). ``bus``: the loop's bus on the channel.
    The driver's default silence, 0.1 s: the simulator answers from a thread of this process,
    and at 8 ms a stall of it under a loaded run tripped the reply watchdog in tests not about
    it (and in the silence test before the bus went silent: 9 commands, then polls)."""
    settings = BusSettings(channel=f"loop_test_{next(_channels)}", fd=protocol.is_fd)
    physics = ActuatorPhysics(PhysicsParams.from_actuator(get_actuator("U10DD")))
    sim = SimulatedActuator(physics, personality, settings).start()
    core = DriverCore(DriverSettings(reply_silence_s=silence_s))
    loop = ControlLoop(ActuatorClient(protocol, bus(settings)), core, rate_hz=rate_hz,
                       reply_timeout_s=0.0015)  # fmt: skip
    faults: list[str] = []
    loop.on_fault = faults.append
    return loop, sim, faults


def close_loop(loop: ControlLoop, sim: SimulatedActuator) -> None:
    loop.stop()
    loop.disable()
    loop.client.close()
    sim.stop()


@pytest.fixture(params=["mit", "odrive", "moteus"])
def rig(request: pytest.FixtureRequest) -> Iterator[tuple[str, ControlLoop, SimulatedActuator]]:
    loop, sim, _ = open_loop(*make(request.param))
    yield request.param, loop, sim
    close_loop(loop, sim)


def recorded_faults(loop: ControlLoop) -> list[str]:
    """The loop's fault reasons from now on."""
    faults: list[str] = []
    loop.on_fault = faults.append
    return faults


def wait_for(condition, timeout_s: float = 3.0) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return False


def test_commands_move_the_simulated_joint(rig: tuple[str, ControlLoop, SimulatedActuator]) -> None:
    name, loop, sim = rig
    assert loop.enable() is not None
    loop.start()
    with loop.lock:
        loop.core.set_target(JointTarget(0.6), time.monotonic())
    band = 0.075 / 2.0 + 0.01  # static friction / k_s, plus the 1-cycle delay of ODrive
    assert wait_for(lambda: abs(sim.physics.state.motor_position_rad - 0.6) < band), name
    # ... and the feedback reports it (a reply or two behind the simulator on a busy machine)
    assert wait_for(
        lambda: (fb := loop.client.last_feedback) is not None and abs(fb.position_rad - 0.6) < band
    ), loop.client.last_feedback
    # the loop keeps cycling (the simulator's arm, in real time, can get there within 40
    # cycles of a loaded loop at 339 Hz)
    assert wait_for(lambda: loop.stats().cycles > 50), loop.stats()
    assert loop.client.counters.malformed == 0
    loop.stop()
    assert loop.disable(), "no answer to disable"
    assert wait_for(lambda: sim.events[EXIT_EVENT[name]] >= 1), sim.events
    sim.silence()
    assert not loop.disable(timeout_s=0.02), "a silent motor's disable said answered"


def test_silent_bus_trips_the_fault_after_the_configured_silence(
    rig: tuple[str, ControlLoop, SimulatedActuator],
) -> None:
    name, loop, sim = rig
    assert loop.enable() is not None
    faults = recorded_faults(loop)
    loop.start()
    assert wait_for(lambda: loop.client.counters.samples > 20)
    assert loop.core.mode is DriverMode.ACTIVE and faults == [], faults
    exits_before = sim.events[EXIT_EVENT[name]]
    sim.silence()
    assert wait_for(lambda: loop.core.mode is DriverMode.FAULT)
    assert len(faults) == 1 and faults[0].startswith("no reply for"), faults
    # read from the fault's own message, written when it tripped: a reply the simulator had
    # queued before the silence may still arrive after it and end the count (CI, loaded: the
    # fault said 4 unanswered at 9 ms, a late reply ended the silence at 14 ms)
    unanswered = re.search(r"\((\d+) requests unanswered\)", faults[0])
    assert unanswered is not None, faults
    assert int(unanswered.group(1)) >= loop.min_unanswered(loop.core) == 25, faults
    # the safe command went out although nothing answers
    assert wait_for(lambda: sim.events[EXIT_EVENT[name]] > exits_before), sim.events
    # in FAULT the motor is polled, never driven; once it answers again its state is
    # published again (the fault stays until re-enabled)
    driven = sim.events[COMMAND_EVENT[name]]
    samples = loop.client.counters.samples
    sim.silence(False)
    assert wait_for(lambda: loop.client.counters.samples > samples + 10), "not polled"
    assert sim.events[COMMAND_EVENT[name]] == driven, sim.events
    assert loop.core.mode is DriverMode.FAULT and not sim.personality.is_enabled()
    # re-enable
    loop.stop()
    assert loop.enable() is not None and loop.core.mode is DriverMode.ACTIVE


@pytest.mark.parametrize(
    ("position", "before", "zeroed"),
    [(0.01, 0.5, True), (0.49, 0.5, False), (-0.3, -0.5, False), (0.2, -0.5, True),
     (0.004, 0.004, True), (0.3, None, True)],
)  # fmt: skip
def test_a_reply_reads_the_new_frame_when_nearer_zero_than_the_old_reading(
    position: float, before: float | None, zeroed: bool
) -> None:
    last = None if before is None else Feedback(before, 0.0, 0.0)
    assert reads_zeroed(position, last) is zeroed


def test_set_zero_does_not_take_an_older_reply_for_its_answer(
    rig: tuple[str, ControlLoop, SimulatedActuator],
) -> None:
    """Replies to commands sent before the zero are still on their way (the device answers
    50 ms late, longer than the 5 ms quiet window): the answer is the reply in the new frame,
    and the motor holds the new zero, not its old reading (CI, loaded: three motors held at
    0.5 rad were told to hold 0.5 in the new frame)."""
    name, loop, sim = rig
    assert loop.enable() is not None
    loop.start()
    with loop.lock:
        loop.core.set_target(JointTarget(0.5), time.monotonic())
    assert wait_for(lambda: (fb := loop.client.last_feedback) is not None
                    and abs(fb.position_rad - 0.5) < 0.05), name  # fmt: skip
    loop.stop()
    sim.faults.reply_delay_s = 0.05
    hold = loop.core.command(time.monotonic())
    assert hold is not None
    for _ in range(3):  # their replies come 50 ms later, in the old frame
        loop.client.send(loop.client.protocol.command_frames(hold, loop.client.last_feedback))
        time.sleep(0.002)
    time.sleep(0.015)
    assert loop.set_zero() is True
    held = loop.core.command(time.monotonic())
    assert held is not None and abs(held.position_rad) < 0.05, (name, held)


def test_set_zero_without_an_answer_faults_and_disables(
    rig: tuple[str, ControlLoop, SimulatedActuator],
) -> None:
    name, loop, sim = rig
    assert loop.enable() is not None
    faults = recorded_faults(loop)
    loop.cycle()
    exits_before = sim.events[EXIT_EVENT[name]]
    sim.silence()
    assert loop.set_zero(timeout_s=0.02) is False
    assert loop.core.mode is DriverMode.FAULT and loop.core.command(time.monotonic()) is None
    assert faults and faults[0].startswith("set_zero: no reply in the new frame"), faults
    assert wait_for(lambda: sim.events[EXIT_EVENT[name]] > exits_before), sim.events


def test_a_device_that_stops_driving_on_its_own_faults_the_driver() -> None:
    """A moteus whose host fell silent for longer than its watchdog (a stalled computer) latches
    its timeout mode and no longer follows; its replies say so. The driver faults and disables
    it (a stop clears the latch) instead of commanding a motor that does not follow; enabling
    again drives it again."""
    loop, sim, faults = open_loop(MoteusProtocol(2, watchdog_timeout_s=0.1), MoteusDevice(2))
    try:
        assert loop.enable() is not None
        loop.start()
        assert wait_for(sim.personality.is_enabled)
        loop.stop()  # the host stalls past the device's 0.1 s watchdog
        assert wait_for(lambda: sim.events["watchdog_timeout"] >= 1), sim.events
        stops = sim.events["mode_stopped"]
        loop.start()
        assert wait_for(lambda: loop.core.mode is DriverMode.FAULT), loop.core.status
        assert faults and "position timeout" in faults[0], faults
        assert sim.events["ignored_while_latched"] >= 1, sim.events  # commands refused
        assert wait_for(lambda: sim.events["mode_stopped"] > stops), sim.events  # cleared
        loop.stop()
        assert loop.enable() is not None and loop.core.mode is DriverMode.ACTIVE
        loop.start()
        assert wait_for(sim.personality.is_enabled), sim.events
    finally:
        close_loop(loop, sim)


def test_a_loop_exception_leaves_the_motor_disabled(
    rig: tuple[str, ControlLoop, SimulatedActuator],
) -> None:
    name, loop, sim = rig
    assert loop.enable() is not None
    errors: list[BaseException] = []
    loop.on_error = errors.append

    def explode(_now: float) -> None:
        raise RuntimeError("boom")

    loop.core.command = explode  # type: ignore[method-assign]
    loop.start()
    assert wait_for(lambda: bool(errors))
    assert loop.core.mode is DriverMode.FAULT and "boom" in loop.core.status.fault_reason
    assert wait_for(lambda: sim.events[EXIT_EVENT[name]] >= 1)


def test_network_interfaces_are_refused() -> None:
    with pytest.raises(BusError, match="network transport"):
        BusSettings(interface="udp_multicast", channel="224.0.0.1").open()
    with pytest.raises(BusError, match="cannot open CAN interface 'socketcan'"):
        BusSettings(interface="socketcan", channel="no_such_can_if").open()


def test_moteus_advances_its_setpoint_with_the_commanded_velocity_between_commands() -> None:
    """moteus firmware integrates control_position with the commanded velocity, so a joint
    keeps tracking a moving setpoint through a gap in the command stream (MIT firmware holds)."""
    protocol, device = MoteusProtocol(2), MoteusDevice(2)
    physics = ActuatorPhysics(PhysicsParams.from_actuator(get_actuator("U10DD")))
    for frame in protocol.enable_frames():
        device.handle(frame, physics, 0.0)
    command = ImpedanceCommand(0.5, 2.0, 10.0, 0.1, 0.0)
    for frame in protocol.command_frames(command, None):
        device.handle(frame, physics, 1.0)
    assert device.time_varying
    law = device.drive_at(1.25)
    assert law(1.0, 2.0) == pytest.approx(0.0, abs=1e-3)  # setpoint 0.5 + 2.0 * 0.25 = 1.0
    assert law(0.5, 2.0) == pytest.approx(10.0 * 0.5, rel=1e-3)
    for frame in protocol.disable_frames():
        device.handle(frame, physics, 1.5)
    assert not device.time_varying


def test_a_gap_in_moteus_commands_does_not_stall_a_moving_joint() -> None:
    now = [0.0]
    protocol, device = MoteusProtocol(2), MoteusDevice(2)
    physics = ActuatorPhysics(PhysicsParams.from_actuator(get_actuator("U10DD")))
    settings = BusSettings(channel=f"loop_test_{next(_channels)}", fd=True)
    sim = SimulatedActuator(physics, device, settings, clock=lambda: now[0])
    for frame in protocol.enable_frames():
        device.handle(frame, physics, 0.0)
    for frame in protocol.command_frames(ImpedanceCommand(0.0, 1.0, 30.0, 0.5, 0.0), None):
        device.handle(frame, physics, 0.0)
    sim.advance_to(0.0)
    sim.advance_to(0.5)  # 0.5 s without a command
    # tracks theta_d = t within the steady error of the impedance law (friction / k_s)
    assert physics.state.motor_position_rad == pytest.approx(0.5, abs=0.08)
    assert physics.state.motor_velocity_rad_s == pytest.approx(1.0, abs=0.1)


def test_a_late_reply_is_published_at_its_bus_time_not_taken_for_the_next_answer() -> None:
    """A reply that missed its cycle is a true sample from the past: handed on with its own
    bus time and counted late; the cycle that finds it still waits for its own answer."""
    settings = BusSettings(channel=f"loop_test_{next(_channels)}", fd=True)
    protocol, device = MoteusProtocol(2), MoteusDevice(2)
    physics = ActuatorPhysics(PhysicsParams.from_actuator(get_actuator("U10DD")))
    device_bus = settings.open(preserve_timestamps=True)
    client = ActuatorClient(protocol, settings.open())
    core = DriverCore(DriverSettings(reply_silence_s=0.008))
    samples: list[tuple[float, float]] = []
    loop = ControlLoop(client, core, rate_hz=500.0, reply_timeout_s=0.001,
                       on_sample=lambda fb, t, _: samples.append((fb.position_rad, t)))  # fmt: skip
    try:
        core.activate(0.0)
        physics.state.motor_position_rad = 0.25
        (reply,) = device.handle(protocol.command_frames(core.command(0.0), None)[0], physics, 0)
        message = to_message(reply)
        on_bus = time.monotonic() - 0.003
        message.timestamp = time.time() - 0.003  # on the bus 3 ms ago
        device_bus.send(message)
        time.sleep(0.01)  # ... and read only now
        loop.cycle()
        assert len(samples) == 1  # the late one; this cycle's own request went unanswered
        position, at_s = samples[0]
        assert position == pytest.approx(0.25, abs=1e-3)
        assert at_s == pytest.approx(on_bus, abs=0.001)
        assert client.counters.late == 1 and core.status.missed_replies_total == 1
    finally:
        client.close()
        device_bus.shutdown()


class StallingSend:
    """A virtual bus whose next send waits ``stall_s`` before the frame goes on the bus: the
    host stalled between computing a command and sending it (a preempted thread)."""

    def __init__(self) -> None:
        self.stalls: list[float] = []

    def open(self, settings: BusSettings) -> can.BusABC:
        return self.wrap(settings.open())

    def wrap(self, bus: can.BusABC) -> can.BusABC:
        send = bus.send

        def stalling(msg: can.Message, timeout: float | None = None) -> None:
            if self.stalls:
                time.sleep(self.stalls.pop())
            send(msg, timeout)

        bus.send = stalling  # type: ignore[method-assign]
        return bus


@pytest.mark.parametrize("name", ["moteus", "mit"])
def test_a_command_that_left_stale_is_sent_again_fresh(name: str) -> None:
    """A host stalled 60 ms between computing a sweep command and sending it: the device would
    take a setpoint 60 ms old (0.38 rad behind at 1 rev/s; a moteus ramps on from it, braking the
    arm). The loop sees its send return late and sends the command again for now: the device
    ends up with the fresh setpoint, and the sample carries the command sent last."""
    stalling = StallingSend()
    # (20 Hz: only a send 25 ms late is stale, so a loaded suite's own stalls do not add to it)
    loop, sim, faults = open_loop(*make(name), rate_hz=20.0, bus=stalling.open)
    applied: list[ImpedanceCommand | None] = []
    loop.on_sample = lambda _fb, _at, command: applied.append(command)
    speed = 2 * 3.141592653589793
    try:
        assert loop.enable() is not None
        start_s = time.monotonic()
        with loop.lock:
            loop.core.set_target(JointTarget(0.0, speed), start_s)
        commands = sim.events[COMMAND_EVENT[name]]
        stalling.stalls.append(0.06)
        loop.cycle()
        assert loop.resent_commands == 1
        assert wait_for(lambda: sim.events[COMMAND_EVENT[name]] >= commands + 2), sim.events
        # the device's setpoint is the fresh one: at least 60 ms of the ramp past the start
        with sim.lock:
            law = sim.personality.drive
        law = getattr(law, "law", law)  # (MIT's, evaluated in its zeroed frame)
        assert isinstance(law, ImpedanceLaw)
        assert law.position_rad >= speed * 0.06, law
        for _ in range(2):  # (no reply within the cycle on a loaded machine: the next has it)
            if not applied:
                loop.cycle()
        assert applied and applied[0] is not None and applied[0].position_rad >= speed * 0.06
        assert faults == []
    finally:
        close_loop(loop, sim)
