"""A simulated actuator on a python-can bus, answering exactly as the firmware does.

The device has its own bus object on the channel (as a real motor has its own transceiver) and
runs in a thread: each received frame first advances the physics to the moment the frame was
put on the bus, then is handled by a *personality* (MIT, ODrive, moteus) that speaks the real wire
protocol, sets the drive law the physics integrates between frames and answers with the state at
that moment. A real device reacts within microseconds of a frame; this thread may be scheduled
milliseconds later, and acting at the frame's bus time keeps that delay out of the physics (the
reply is only delivered late). Between frames the physics keeps running, idle ticks included.
Physics: :mod:`transparency_ros.core.actuator_physics` (the one implementation).

Fault injection for tests, all on the wire: :meth:`SimulatedActuator.silence` stops all replies,
as a cut cable or a dead controller would; :attr:`SimulatedActuator.faults` (:class:`DeviceFaults`)
duplicates or storms replies, delays them, adds error frames or refuses motor mode;
:meth:`SimulatedActuator.inject` puts any frame on the bus.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace

import can

from transparency_ros.canbus import mit, moteus_fd, odrive
from transparency_ros.canbus.client import BusSettings, to_frame, to_message
from transparency_ros.canbus.clock import WALL
from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError
from transparency_ros.canbus.protocol import Frame
from transparency_ros.core.actuator_physics import (
    ActuatorPhysics,
    ConstantTorque,
    DriveLaw,
    ImpedanceLaw,
    zero_drive,
)

TWO_PI = 2.0 * math.pi


class Personality(ABC):
    """Device side of one protocol. Subclasses record what they saw in ``events``."""

    def __init__(self, gear_ratio: float = 1.0) -> None:
        self.gear_ratio = gear_ratio
        self.drive: DriveLaw = zero_drive
        self.events: Counter[str] = Counter()
        self.zero_offset_rad = 0.0  # output side

    @abstractmethod
    def handle(self, frame: Frame, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        """React to one frame; return the frames the device sends back."""

    def tick(self, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        """Called on idle ticks too: cyclic messages and watchdogs."""
        return []

    def drive_at(self, now_s: float) -> DriveLaw:
        """The law the firmware runs at ``now_s``; by default the last one set, held."""
        return self.drive

    @property
    def time_varying(self) -> bool:
        """Whether :meth:`drive_at` changes between frames (the firmware runs a trajectory)."""
        return False

    @abstractmethod
    def is_enabled(self) -> bool:
        """Whether the firmware would drive the motor now (motor mode / closed loop / position)."""

    @abstractmethod
    def addressed(self, frame: Frame) -> bool:
        """Whether ``frame`` is for this device (a bus of several devices routes by it)."""

    def position_out(self, physics: ActuatorPhysics) -> float:
        return physics.measured_position_rad - self.zero_offset_rad


class MitDevice(Personality):
    """mini-cheetah / AK firmware: replies to every frame addressed to it with its state."""

    def __init__(
        self,
        motor_id: int = 1,
        limits: mit.MitLimits | None = None,
        *,
        master_id: int = 0,
        ak_reply: bool = False,
        gear_ratio: float = 1.0,
    ) -> None:
        super().__init__(gear_ratio)
        self.motor_id, self.master_id, self.ak_reply = motor_id, master_id, ak_reply
        self.limits = limits or mit.MitLimits()
        self.enabled = False

    def is_enabled(self) -> bool:
        return self.enabled

    def addressed(self, frame: Frame) -> bool:
        return frame.arbitration_id == self.motor_id and not frame.is_remote

    def _reply(self, physics: ActuatorPhysics) -> Frame:
        g = self.gear_ratio
        data = mit.encode_reply(
            self.motor_id & 0xFF,
            self.position_out(physics) * g,
            physics.velocity_rad_s * g,
            physics.state.applied_torque_nm / g,
            self.limits,
            temperature_raw=65 if self.ak_reply else None,
            error_code=0 if self.ak_reply else None,
        )
        return Frame(self.master_id, data)

    def handle(self, frame: Frame, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        if frame.arbitration_id != self.motor_id or frame.is_remote:
            return []
        if len(frame.data) != 8:
            self.events["malformed"] += 1
            return []  # the firmware ignores frames of the wrong length
        special = mit.SPECIAL_FRAMES.get(bytes(frame.data))
        if special == "enter":
            self.enabled = True
        elif special == "exit":
            self.enabled = False
            self.drive = zero_drive
        elif special == "zero":
            self.zero_offset_rad = physics.measured_position_rad
        else:
            special = "command"
            if self.enabled:
                cmd = mit.decode_command(frame.data, self.limits)
                g = self.gear_ratio
                self.drive = _OffsetLaw(
                    ImpedanceLaw(
                        cmd.kp * g * g,
                        cmd.kd * g * g,
                        cmd.position_rad / g,
                        cmd.velocity_rad_s / g,
                        cmd.torque_nm * g,
                    ),
                    self.zero_offset_rad,
                )
        self.events[special] += 1
        return [self._reply(physics)]


class ODriveDevice(Personality):
    """ODrive firmware 0.6: answers RTR requests, sends a heartbeat every 100 ms."""

    HEARTBEAT_PERIOD_S = 0.1

    def __init__(self, node_id: int = 0, *, gear_ratio: float = 1.0) -> None:
        super().__init__(gear_ratio)
        self.node_id = node_id
        self.axis_state = odrive.AxisState.IDLE
        self.control_mode = odrive.ControlMode.POSITION
        self.torque_setpoint_nm = 0.0  # native (motor side)
        self._last_heartbeat_s = -math.inf

    def _id(self, cmd: odrive.Cmd) -> int:
        return odrive.arbitration_id(self.node_id, cmd)

    def is_enabled(self) -> bool:
        return self.axis_state == odrive.AxisState.CLOSED_LOOP_CONTROL

    def addressed(self, frame: Frame) -> bool:
        return frame.arbitration_id <= 0x7FF and (
            odrive.split_id(frame.arbitration_id)[0] == self.node_id
        )

    def _apply(self) -> None:
        closed = self.axis_state == odrive.AxisState.CLOSED_LOOP_CONTROL
        if closed and self.control_mode == odrive.ControlMode.TORQUE:
            self.drive = ConstantTorque(self.torque_setpoint_nm * self.gear_ratio)
        else:
            self.drive = zero_drive

    def handle(self, frame: Frame, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        if frame.arbitration_id > 0x7FF:
            return []
        node, cmd = odrive.split_id(frame.arbitration_id)
        if node != self.node_id:
            return []
        g = self.gear_ratio
        try:
            if frame.is_remote and cmd == odrive.Cmd.GET_ENCODER_ESTIMATES:
                self.events["get_encoder_estimates"] += 1
                est = odrive.EncoderEstimates(
                    self.position_out(physics) * g / TWO_PI, physics.velocity_rad_s * g / TWO_PI
                )
                return [
                    Frame(
                        self._id(odrive.Cmd.GET_ENCODER_ESTIMATES),
                        odrive.encode_encoder_estimates(est),
                    )
                ]
            if frame.is_remote and cmd == odrive.Cmd.GET_TORQUES:
                self.events["get_torques"] += 1
                torque = physics.state.applied_torque_nm / g
                return [
                    Frame(
                        self._id(odrive.Cmd.GET_TORQUES),
                        odrive.encode_torques(odrive.Torques(self.torque_setpoint_nm, torque)),
                    )
                ]
            if cmd == odrive.Cmd.SET_AXIS_STATE:
                self.axis_state = odrive.AxisState(odrive.decode_set_axis_state(frame.data))
                self.events[f"axis_state_{self.axis_state.name.lower()}"] += 1
            elif cmd == odrive.Cmd.SET_CONTROLLER_MODE:
                control, _ = odrive.decode_set_controller_mode(frame.data)
                self.control_mode = odrive.ControlMode(control)
                self.events["set_controller_mode"] += 1
            elif cmd == odrive.Cmd.SET_INPUT_TORQUE:
                self.torque_setpoint_nm = odrive.decode_set_input_torque(frame.data)
                self.events["set_input_torque"] += 1
            else:
                self.events["ignored"] += 1
        except (MalformedFrameError, ValueError):
            self.events["malformed"] += 1
        self._apply()
        return []

    def tick(self, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        if now_s - self._last_heartbeat_s < self.HEARTBEAT_PERIOD_S:
            return []
        self._last_heartbeat_s = now_s
        hb = odrive.Heartbeat(0, int(self.axis_state), 0, True)
        return [Frame(self._id(odrive.Cmd.HEARTBEAT), odrive.encode_heartbeat(hb))]


# moteus modes a controller stays in until commanded to stop (its watchdog's timeout, a fault)
LATCHED = (moteus_fd.Mode.TIMEOUT, moteus_fd.Mode.FAULT)


class MoteusDevice(Personality):
    """moteus: register writes set the mode and position-mode terms; reads are answered. Not
    commanded within the watchdog time the host wrote, it enters the position-timeout mode
    (damping only) and, as the firmware does, stays there until a stop command: later position
    commands are ignored (counted as ``ignored_while_latched``) and the replies say the mode."""

    def __init__(
        self,
        device_id: int = 1,
        *,
        kp_nm_per_rev: float = 200.0,
        kd_nms_per_rev: float = 5.0,
        gear_ratio: float = 1.0,
    ) -> None:
        super().__init__(gear_ratio)
        self.device_id = device_id
        self.kp, self.kd = kp_nm_per_rev, kd_nms_per_rev
        self.mode = moteus_fd.Mode.STOPPED
        self.registers: dict[int, float] = {}
        self._watchdog_deadline_s = math.inf
        self._command_s = 0.0  # when the last position-mode command arrived

    def is_enabled(self) -> bool:
        return self.mode == moteus_fd.Mode.POSITION

    def addressed(self, frame: Frame) -> bool:
        return moteus_fd.split_id(frame.arbitration_id)[1] == self.device_id

    def _apply(self, now_s: float) -> None:
        r = self.registers
        if self.mode is moteus_fd.Mode.TIMEOUT:
            return  # the watchdog's damping holds (tick) until a stop
        if self.mode != moteus_fd.Mode.POSITION:
            self.drive = zero_drive
            return
        g = self.gear_ratio
        position = r.get(moteus_fd.Reg.COMMAND_POSITION, math.nan)
        kp_scale = r.get(moteus_fd.Reg.COMMAND_KP_SCALE, 1.0)
        kd_scale = r.get(moteus_fd.Reg.COMMAND_KD_SCALE, 1.0)
        law = ImpedanceLaw(
            kp=0.0 if math.isnan(position) else self.kp * kp_scale * g * g / TWO_PI,
            kd=self.kd * kd_scale * g * g / TWO_PI,
            position_rad=0.0 if math.isnan(position) else position * TWO_PI / g,
            velocity_rad_s=r.get(moteus_fd.Reg.COMMAND_VELOCITY, 0.0) * TWO_PI / g,
            torque_ff_nm=r.get(moteus_fd.Reg.COMMAND_FEEDFORWARD_TORQUE, 0.0) * g,
        )
        self.drive = law
        self._command_s = now_s
        timeout = r.get(moteus_fd.Reg.COMMAND_TIMEOUT, math.nan)
        self._watchdog_deadline_s = now_s + timeout if math.isfinite(timeout) else math.inf

    def handle(self, frame: Frame, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        source, destination, reply = moteus_fd.split_id(frame.arbitration_id)
        if destination != self.device_id or frame.is_remote:
            return []
        try:
            subframes = moteus_fd.parse_frame(frame.data)
        except MalformedFrameError:
            self.events["malformed"] += 1
            return []
        reads: dict[int, moteus_fd.Res] = {}
        for sub in subframes:
            if sub.op == moteus_fd.WRITE and sub.value is not None:
                if sub.register == moteus_fd.Reg.MODE:
                    mode = moteus_fd.Mode(int(sub.value))
                    if self.mode in LATCHED and mode is not moteus_fd.Mode.STOPPED:
                        self.events["ignored_while_latched"] += 1  # a stop clears it
                        continue
                    self.mode = mode
                    self.events[f"mode_{self.mode.name.lower()}"] += 1
                else:
                    self.registers[sub.register] = float(sub.value)
            elif sub.op == moteus_fd.READ and sub.resolution is not None:
                reads[sub.register] = sub.resolution
        self._apply(now_s)
        if not (reply and reads):
            return []
        g = self.gear_ratio
        state: dict[int, float] = {
            moteus_fd.Reg.MODE: float(self.mode),
            moteus_fd.Reg.POSITION: self.position_out(physics) * g / TWO_PI,
            moteus_fd.Reg.VELOCITY: physics.velocity_rad_s * g / TWO_PI,
            moteus_fd.Reg.TORQUE: physics.state.applied_torque_nm / g,
            moteus_fd.Reg.VOLTAGE: 24.0,
            moteus_fd.Reg.TEMPERATURE: 30.0,
            moteus_fd.Reg.FAULT: 0.0,
        }
        values = {reg: (state.get(reg, math.nan), res) for reg, res in reads.items()}
        payload = moteus_fd.pad_fd(moteus_fd.encode_values(moteus_fd.REPLY, values))
        arb = moteus_fd.arbitration_id(self.device_id, source, reply=False)
        return [Frame(arb, payload, is_fd=True, is_extended_id=True)]

    def drive_at(self, now_s: float) -> DriveLaw:
        """moteus advances its control position with the commanded velocity between commands
        (reference: control_position = command_position OR control_position + velocity dt), so
        a late command does not leave a moving joint pulling back to a stale setpoint."""
        law = self.drive
        if isinstance(law, ImpedanceLaw) and law.kp > 0.0 and law.velocity_rad_s != 0.0:
            return replace(
                law, position_rad=law.position_rad + law.velocity_rad_s * (now_s - self._command_s)
            )
        return law

    @property
    def time_varying(self) -> bool:
        return self.mode == moteus_fd.Mode.POSITION

    def tick(self, physics: ActuatorPhysics, now_s: float) -> list[Frame]:
        if self.mode == moteus_fd.Mode.POSITION and now_s > self._watchdog_deadline_s:
            self.mode = moteus_fd.Mode.TIMEOUT
            self.events["watchdog_timeout"] += 1
            self.drive = ImpedanceLaw(0.0, self.kd * self.gear_ratio**2 / TWO_PI, 0.0, 0.0, 0.0)
        return []


class _OffsetLaw:
    """Evaluate a law in the device's zeroed frame (position reads zero at the set-zero point)."""

    def __init__(self, law: DriveLaw, offset_rad: float) -> None:
        self.law, self.offset_rad = law, offset_rad

    def __call__(self, position: float, velocity: float) -> float:
        return self.law(position - self.offset_rad, velocity)


@dataclass
class DeviceFaults:
    """What the simulated device does wrong, on the wire, as a real device or its bus can
    (issue 8's fault injection). Change the fields of :attr:`SimulatedActuator.faults` while
    it runs; :meth:`SimulatedActuator.inject` puts arbitrary frames on the bus."""

    reply_copies: int = 1  # 2: every reply duplicated; 20: a reply storm
    reply_delay_s: float = 0.0  # every reply goes on the wire this much later (the device keeps up)
    refuse_enable: bool = False  # never enters motor mode: while disabled it ignores every frame
    error_frames: int = 0  # error frames (a controller in trouble) sent with every reply


class SimulatedActuator:
    """A device on the bus: its own python-can bus object, a thread, the physics."""

    def __init__(
        self,
        physics: ActuatorPhysics,
        personality: Personality,
        bus_settings: BusSettings | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        idle_tick_s: float = 0.002,
    ) -> None:
        self.physics = physics
        self.personality = personality
        self.settings = bus_settings or BusSettings()
        if self.settings.interface != "virtual":
            raise CanProtocolError("the simulated actuator only attaches to a 'virtual' bus")
        self.clock = clock
        self.idle_tick_s = idle_tick_s
        self.lock = threading.Lock()
        self._silent = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._bus: can.BusABC | None = None
        self._last_s: float | None = None
        self.start_monotonic_s = 0.0
        self.replies_sent = 0
        self.frames_received = 0
        self.faults = DeviceFaults()
        self.last_reply: Frame | None = None  # the newest reply frame the device sent
        self._injected: list[can.Message] = []
        self._delayed: list[tuple[float, can.Message]] = []  # (due on the clock, message)

    def start(self) -> SimulatedActuator:
        if self._thread is not None:
            return self
        self._bus = self.settings.open(preserve_timestamps=True)
        self._last_s = self.clock()
        # physics time t corresponds to clock() = start_monotonic_s + t
        self.start_monotonic_s = self._last_s - self.physics.state.time_s
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="simulated_actuator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Switch the device off. Frames already on the wire to it are taken first, as a real
        device takes them: on a loaded machine the thread can lag, and the disable frames sent
        just before would otherwise be lost here, not on the bus."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._bus is not None:
            self._take_pending(self._bus)
            self._bus.shutdown()
            self._bus = None

    def _take_pending(self, bus: can.BusABC) -> None:
        with self.lock:
            while True:
                try:
                    msg = bus.recv(timeout=0.0)
                except (can.CanError, OSError):
                    return
                if msg is None:
                    return
                self.frames_received += 1
                if not (self.faults.refuse_enable and not self.personality.is_enabled()):
                    self.personality.handle(to_frame(msg), self.physics, self.clock())

    def __enter__(self) -> SimulatedActuator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def silence(self, silent: bool = True) -> None:
        """Stop (or resume) answering, as a cut cable would."""
        if silent:
            self._silent.set()
        else:
            self._silent.clear()

    def inject(self, *frames: Frame | can.Message) -> None:
        """Send these frames from the device's bus on its next turn (garbage, unknown ids, wrong
        lengths, error frames: ``can.Message(is_error_frame=True)``)."""
        with self.lock:
            self._injected += [f if isinstance(f, can.Message) else to_message(f) for f in frames]

    @property
    def events(self) -> Counter[str]:
        with self.lock:
            return Counter(self.personality.events)

    def advance_to(self, now: float) -> None:
        """Integrate up to clock time ``now`` (the device thread does so on every frame and idle
        tick; with a controlled clock, tests call it directly)."""
        last = self._last_s if self._last_s is not None else now
        device = self.personality
        if now > last and not device.time_varying:
            self.physics.advance(now - last, device.drive)
        elif now > last:  # the firmware's setpoint moves: re-evaluate it every physics step
            steps = math.ceil((now - last) / self.physics.max_step_s)
            dt = (now - last) / steps
            for i in range(steps):
                self.physics.advance(dt, device.drive_at(last + (i + 0.5) * dt))
        self._last_s = now

    def _run(self) -> None:
        bus = self._bus
        assert bus is not None
        while not self._stop.is_set():
            wait = self.idle_tick_s
            if self._delayed:
                wait = min(wait, max(0.0, self._delayed[0][0] - self.clock()))
            try:
                msg = bus.recv(timeout=wait)
            except (can.CanError, OSError):
                continue
            self._send_due(bus)
            with self.lock:
                now = self.clock()
                if msg is not None:  # act at the frame's bus time (it may have waited for us)
                    waited = max(0.0, WALL(now) - msg.timestamp)
                    last = self._last_s if self._last_s is not None else now
                    now = max(last, now - waited)
                self.advance_to(now)
                if msg is not None:
                    self.frames_received += 1
                faults = self.faults
                ignoring = faults.refuse_enable and not self.personality.is_enabled()
                out = (
                    self.personality.handle(to_frame(msg), self.physics, now)
                    if msg is not None and not ignoring
                    else []
                )
                out += self.personality.tick(self.physics, now)
                injected, self._injected = self._injected, []
            for message in injected:
                with contextlib.suppress(can.CanError, OSError):
                    bus.send(message)
            if self._silent.is_set() or not out:
                continue
            due = now + faults.reply_delay_s
            sent_at = WALL(due)  # the bus time the replies go on the wire
            extra = [can.Message(is_error_frame=True, timestamp=sent_at)] * faults.error_frames
            for frame in out * max(1, faults.reply_copies):
                message = to_message(frame)
                message.timestamp = sent_at
                self.last_reply = frame
                if faults.reply_delay_s > 0:
                    self._delayed.append((due, message))
                    continue
                try:
                    bus.send(message)
                    self.replies_sent += 1
                except (can.CanError, OSError):
                    continue
            for message in extra:
                with contextlib.suppress(can.CanError, OSError):
                    bus.send(message)

    def _send_due(self, bus: can.BusABC) -> None:
        now = self.clock()
        while self._delayed and self._delayed[0][0] <= now:
            _, message = self._delayed.pop(0)
            with contextlib.suppress(can.CanError, OSError):
                bus.send(message)
                self.replies_sent += 1
