"""Several motors in one loop (canbus.multi) against simulated devices sharing virtual buses."""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

from test.unit.canbus.test_loop_with_sim import StallingSend, make
from transparency_ros.canbus.client import BusSettings
from transparency_ros.canbus.multi import Motor, MultiControlLoop, RobotSample
from transparency_ros.canbus.protocol import (
    MitProtocol,
)
from transparency_ros.canbus.sim_robot import SimulatedBus, SimulatedBuses
from transparency_ros.core.actuator_physics import ActuatorPhysics, PhysicsParams
from transparency_ros.core.config import get_actuator
from transparency_ros.core.driver import DriverCore, DriverMode, DriverSettings, JointTarget
from transparency_ros.ros.actuator_driver.hardware import ROBOT_SIM_STEP_S

_channels = itertools.count()


@dataclass
class Robot:
    loop: MultiControlLoop
    sims: list[SimulatedBus]
    samples: list[RobotSample]
    faults: list[str]
    runner: SimulatedBuses

    def sim_of(self, index: int) -> tuple[SimulatedBus, int]:
        """The simulated bus and device index of motor ``index``."""
        bus = self.loop.motors[index].bus
        on_bus = [i for i, m in enumerate(self.loop.motors) if m.bus == bus]
        return self.sims[bus], on_bus.index(index)


def build(
    protocol: str, ids: list[int], buses: int = 1, policy: str = "all", rate_hz: float = 500.0
) -> Robot:
    per_bus = [ids[b::buses] for b in range(buses)]
    motors: list[Motor] = []
    sims, opened = [], []
    for b, bus_ids in enumerate(per_bus):
        settings = BusSettings(channel=f"multi_{next(_channels)}", fd=protocol == "moteus")
        devices = []
        for motor_id in bus_ids:
            host, device = make(protocol, motor_id)
            physics = ActuatorPhysics(
                PhysicsParams.from_actuator(get_actuator("U10DD")), max_step_s=ROBOT_SIM_STEP_S
            )
            devices.append((physics, device))
            # (the simulated motors answer from a thread of this test process, stalled with it
            # under load: at 8 ms (4 cycles), a 279 ms stall of the whole suite's process ended
            # with the loop's thread sending 3 requests before the motors' thread answered, a
            # "silent" motor. A real motor does not stall with the host; 0.1 s, the driver's
            # default, keeps that ordering from looking like silence)
            core = DriverCore(DriverSettings(reply_silence_s=0.1))
            motors.append(Motor(f"j{motor_id}", host, core, bus=b))
        sims.append(SimulatedBus(devices, settings))
        opened.append(settings.open())
    runner = SimulatedBuses(sims).start()  # one thread for all buses, as the node runs them
    robot = Robot(None, sims, [], [], runner)  # type: ignore[arg-type]
    robot.loop = MultiControlLoop(
        opened, motors, rate_hz=rate_hz, reply_timeout_s=0.0018, fault_policy=policy,
        on_sample=robot.samples.append, on_fault=robot.faults.append,
    )  # fmt: skip
    return robot


@pytest.fixture
def robot(request: pytest.FixtureRequest) -> Iterator[Robot]:
    robot = build(*request.param)
    yield robot
    robot.loop.stop()
    robot.loop.disable()
    robot.loop.close()
    robot.runner.stop()
    assert not any(any(sim.enabled()) for sim in robot.sims), "a motor was left enabled"


def wait_for(condition, timeout_s: float = 3.0) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return False


def assert_the_others_follow_the_policy(loop: MultiControlLoop, sim: SimulatedBus) -> None:
    """j2 (of three on one bus) was stopped: with fault_policy all the others are stopped with
    it, with motor they keep being driven."""
    others = [loop.motors[i].core.mode for i in (0, 2)]
    if loop.fault_policy == "all":
        assert others == [DriverMode.FAULT] * 2
        assert wait_for(lambda: not any(sim.enabled()))
    else:
        assert others == [DriverMode.ACTIVE] * 2
        assert sim.enabled() == [True, False, True]


@pytest.mark.parametrize(
    "robot",
    [("mit", [1, 2, 3], 1, "all"), ("odrive", [3, 4, 5], 1, "all"),
     ("moteus", [1, 2, 3], 1, "all"), ("mit", [1, 2, 3, 4, 5, 6], 2, "all")],
    indirect=True, ids=["mit", "odrive", "moteus", "mit-two-buses"],
)  # fmt: skip
def test_every_motor_follows_its_own_target(robot: Robot) -> None:
    loop = robot.loop
    assert loop.enable() == []
    loop.start()  # (moteus enters position mode with the first command)
    assert wait_for(lambda: all(all(sim.enabled()) for sim in robot.sims))
    targets = [0.1 * (i + 1) * (-1) ** i for i in range(len(loop.motors))]
    with loop.lock:
        for motor, target in zip(loop.motors, targets, strict=True):
            motor.core.set_target(JointTarget(target), time.monotonic())

    def settled() -> bool:
        last = robot.samples[-1] if robot.samples else None
        if last is None or len(last.indices) != len(loop.motors):
            return False
        return all(abs(fb.position_rad - targets[i]) < 0.03
                   for i, fb in zip(last.indices, last.feedback, strict=True))  # fmt: skip

    assert wait_for(settled, 5.0), robot.samples[-1] if robot.samples else "no samples"
    stamps = [s.stamp_s for s in robot.samples]
    assert all(b > a for a, b in itertools.pairwise(stamps))
    assert robot.faults == []
    loop.stop()
    loop.disable()
    # the frames are sent; the simulated motors act on them from their own thread, which a stall
    # of this process delays (a real motor does not stall with the host)
    assert wait_for(lambda: not any(any(sim.enabled()) for sim in robot.sims), 1.0)


@pytest.mark.parametrize(
    "robot", [("mit", [1, 2, 3], 1, "all"), ("mit", [1, 2, 3], 1, "motor")],
    indirect=True, ids=["policy-all", "policy-motor"],
)  # fmt: skip
def test_a_silent_motor_trips_its_own_watchdog(robot: Robot) -> None:
    loop = robot.loop
    assert loop.enable() == []
    loop.start()
    sim, device = robot.sim_of(1)
    sim.silence(device)
    assert wait_for(lambda: loop.motors[1].core.mode is DriverMode.FAULT)
    assert wait_for(lambda: len(robot.faults) >= 1)
    assert robot.faults[0].startswith("j2: ")
    silent = sim.personalities[device]
    assert wait_for(lambda: not silent.is_enabled()), "the silent motor was not sent disable"
    assert_the_others_follow_the_policy(loop, sim)
    # driven or disabled, the motors that answer keep being published (disabled ones polled)
    count = len(robot.samples)
    time.sleep(0.1)
    assert len(robot.samples) > count + 10
    # (a loaded run's newest sample can miss a late reply: the others, within a few samples)
    assert wait_for(lambda: robot.samples[-1].indices == (0, 2)), "the others keep being published"
    # and once the silent one answers again, it is published again, still disabled
    sim.silence(device, False)
    assert wait_for(lambda: robot.samples[-1].indices == (0, 1, 2))
    assert not silent.is_enabled() and loop.motors[1].core.mode is DriverMode.FAULT


@pytest.mark.parametrize("robot", [("mit", [1, 2], 1, "all")], indirect=True)
def test_enable_names_the_motor_that_does_not_answer(robot: Robot) -> None:
    sim, device = robot.sim_of(1)
    sim.silence(device)
    assert robot.loop.enable(timeout_s=0.05) == ["j2"]
    assert robot.loop.motors[1].core.mode is DriverMode.FAULT
    # disable names the motor that did not answer it either (whether it took it is unknown)
    assert robot.loop.disable() == ["j2"]
    assert not any(sim.enabled())


@pytest.mark.parametrize(
    "robot", [(p, [1, 2, 3], 1, "all") for p in ("mit", "odrive", "moteus")],
    indirect=True, ids=["mit", "odrive", "moteus"],
)  # fmt: skip
def test_disable_waits_for_every_motors_answer(robot: Robot) -> None:
    loop = robot.loop
    assert loop.enable() == []
    loop.start()
    assert wait_for(lambda: len(robot.samples) > 10)
    loop.stop()
    assert loop.disable() == []
    assert all(m.core.mode is DriverMode.INACTIVE for m in loop.motors)
    # (the answer follows the disable on the wire, but may be one to the loop's last request:
    # the simulated motors' thread can lag this process; a real motor takes frames in order)
    assert wait_for(lambda: not any(any(sim.enabled()) for sim in robot.sims), 1.0)


@pytest.mark.parametrize("robot", [("mit", [1, 2], 1, "all")], indirect=True)
def test_an_error_inside_the_loop_disables_every_motor(robot: Robot) -> None:
    loop = robot.loop
    errors: list[BaseException] = []
    loop.on_error = errors.append
    assert loop.enable() == []
    loop.on_sample = lambda _s: (_ for _ in ()).throw(RuntimeError("subscriber blew up"))
    loop.start()
    assert wait_for(lambda: bool(errors))
    assert all(m.core.mode is DriverMode.FAULT for m in loop.motors)
    assert wait_for(lambda: not any(robot.sims[0].enabled()))


@pytest.mark.parametrize("robot", [("mit", [1, 2, 3], 1, "all")], indirect=True)
def test_set_zero_zeroes_every_motor(robot: Robot) -> None:
    loop = robot.loop
    assert loop.enable() == []
    loop.start()
    with loop.lock:
        for motor in loop.motors:
            motor.core.set_target(JointTarget(0.5), time.monotonic())
    assert wait_for(lambda: bool(robot.samples) and min(
        fb.position_rad for fb in robot.samples[-1].feedback) > 0.45)  # fmt: skip
    assert loop.set_zero() == []
    robot.samples.clear()
    assert wait_for(lambda: len(robot.samples) > 20)
    assert all(abs(fb.position_rad) < 0.03 for fb in robot.samples[-1].feedback)


@pytest.mark.parametrize(
    "robot", [("mit", [1, 2, 3], 1, "all"), ("mit", [1, 2, 3], 1, "motor")],
    indirect=True, ids=["policy-all", "policy-motor"],
)  # fmt: skip
def test_a_zero_without_an_answer_faults_and_disables(robot: Robot) -> None:
    """Whether a silent motor's frame moved is unknown: it is not driven on either reading."""
    loop = robot.loop
    assert loop.enable() == []
    loop.cycle()
    sim, device = robot.sim_of(1)
    sim.silence(device)
    assert loop.set_zero(timeout_s=0.02) == ["j2"]
    assert loop.motors[1].core.mode is DriverMode.FAULT
    assert robot.faults and robot.faults[0].startswith("j2: set_zero: no reply in the new frame")
    assert wait_for(lambda: not sim.personalities[device].is_enabled())
    assert_the_others_follow_the_policy(loop, sim)


@pytest.mark.parametrize("robot", [("moteus", [1, 2, 3], 1, "motor")], indirect=True)
def test_motors_that_stop_driving_on_their_own_fault_the_driver(robot: Robot) -> None:
    """The loop stalls past the moteus' watchdog (0.1 s, the default, here): each latches its
    timeout, says so in its replies, and is faulted and disabled by the driver (even with
    fault_policy motor, since each reports it); enabling again drives them again."""
    loop = robot.loop
    for motor in loop.motors:  # (written with every command)
        motor.protocol.watchdog_timeout_s = 0.1  # type: ignore[attr-defined]
    assert loop.enable() == []
    loop.start()
    sim = robot.sims[0]
    assert wait_for(lambda: all(sim.enabled()))
    loop.stop()
    time.sleep(0.3)
    loop.start()
    assert wait_for(lambda: all(m.core.mode is DriverMode.FAULT for m in loop.motors))
    assert len(robot.faults) == 3 and all(
        "the device reports: moteus position timeout" in f for f in robot.faults
    ), robot.faults
    loop.stop()
    assert loop.enable() == []
    loop.start()
    assert wait_for(lambda: all(sim.enabled())), sim.enabled()


def test_bad_configurations_are_refused() -> None:
    core = DriverCore(DriverSettings())
    bus = BusSettings(channel=f"multi_{next(_channels)}").open()
    try:
        twins = [Motor("a", MitProtocol(1), core), Motor("a", MitProtocol(2), core)]
        with pytest.raises(ValueError, match="unique"):
            MultiControlLoop([bus], twins, rate_hz=1000, reply_timeout_s=1e-3)
        same_id = [Motor("a", MitProtocol(1), core), Motor("b", MitProtocol(0x101), core)]
        with pytest.raises(ValueError, match="same id"):
            MultiControlLoop([bus], same_id, rate_hz=1000, reply_timeout_s=1e-3)
        with pytest.raises(ValueError, match="fault_policy"):
            MultiControlLoop([bus], [Motor("a", MitProtocol(1), core)], rate_hz=1000,
                             reply_timeout_s=1e-3, fault_policy="some")  # fmt: skip
        with pytest.raises(ValueError, match="bus 1 has no motor"):
            MultiControlLoop([bus, bus], [Motor("a", MitProtocol(1), core)], rate_hz=1000,
                             reply_timeout_s=1e-3)  # fmt: skip
    finally:
        bus.shutdown()


# (20 Hz: only a send 25 ms late is stale, so a loaded suite's own stalls (one more resend at
# 100 Hz) do not add to the one made here; the wait for replies is 3.6 ms)
@pytest.mark.parametrize("robot", [("moteus", [1, 2], 1, "all", 20.0)], indirect=True)
def test_commands_that_left_stale_are_sent_again_fresh(robot: Robot) -> None:
    """The host stalled 60 ms sending the first motor's sweep command (canbus test_loop_with_sim
    has the single-motor case): the loop sends that motor its command again, for now (each
    motor's send is timed on its own: the second's was not late); the reply to the stale one is
    counted superseded, and the sample carries fresh commands."""
    loop = robot.loop
    stalling = StallingSend()
    stalling.wrap(loop.clients[0].bus)
    speed = 6.283
    assert loop.enable() == []
    with loop.lock:
        for motor in loop.motors:
            motor.core.set_target(JointTarget(0.0, speed), time.monotonic())
    stalling.stalls.append(0.06)
    loop.cycle()
    assert loop.resent_commands == 1
    first = len(robot.samples)
    # j1 answered both its sends: the stale one's reply superseded, or (the fresh one's after
    # the cycle's wait) read late by the next cycle
    loop.cycle()
    assert first > 0, "no reply within the cycle"
    commands = robot.samples[0].commands
    assert all(c is not None and c.position_rad >= speed * 0.06 for c in commands), commands
    j1, j2 = loop.motors
    assert j1.superseded + j1.late >= 1 and j2.superseded == 0, loop.motors
    assert robot.faults == []
