"""One actuator interface over the three wire protocols, in SI units at the output.

An adapter turns intentions (enable, disable, zero, an impedance command) into frames and
frames into :class:`Feedback`. It holds no bus: ``canbus.client.ActuatorClient`` does the
I/O. ``gear_ratio`` converts the device's native units (motor side) to the output:
position_out = native / gear_ratio, torque_out = native * gear_ratio (1 when the device already
reports at the output, as AK motors and moteus with ``rotor_to_output_ratio`` do).

Where the impedance law runs:
* MIT: in the motor (kp, kd, p_d, v_d, tau_ff in every frame), at the firmware's loop rate;
* moteus: in the controller, position mode with kp/kd scales of its configured gains;
* ODrive: on the host (torque mode): tau = k_s (p_d - p) + k_d (v_d - v) + tau_ff from the latest
  encoder estimate, sent as Set_Input_Torque; one cycle of delay, stated in the README.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import NamedTuple

from transparency_ros.canbus import mit, moteus_fd, odrive
from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError
from transparency_ros.core.driver import ImpedanceCommand
from transparency_ros.core.errors import shown

TWO_PI = 2.0 * math.pi


class Frame(NamedTuple):
    """A CAN frame without a bus: what codecs produce and consume."""

    arbitration_id: int
    data: bytes
    is_fd: bool = False
    is_remote: bool = False
    is_extended_id: bool = False


@dataclass(frozen=True)
class Feedback:
    """One sample of the actuator at the output."""

    position_rad: float
    velocity_rad_s: float
    torque_nm: float
    # what the device says stops it driving the motor, in its own words ("": nothing, or a
    # protocol whose replies do not say): moteus' fault and latched watchdog modes
    device_fault: str = ""


class ActuatorProtocol(ABC):
    """Host side of one actuator on a CAN bus."""

    name: str
    is_fd: bool = False

    def __init__(self, gear_ratio: float = 1.0) -> None:
        if not (math.isfinite(gear_ratio) and gear_ratio > 0):
            raise CanProtocolError(f"gear_ratio must be > 0, got {shown(gear_ratio)}")
        self.gear_ratio = gear_ratio
        self.zero_offset_rad = 0.0  # host-side zero (protocols without a zero command)

    @abstractmethod
    def enable_frames(self) -> list[Frame]: ...

    @abstractmethod
    def disable_frames(self) -> list[Frame]:
        """Zero torque, then release the motor (motor mode off / idle / stopped)."""

    @abstractmethod
    def zero_frames(self, last: Feedback | None) -> list[Frame]:
        """Make the current position read zero."""

    @abstractmethod
    def query_frames(self) -> list[Frame]:
        """Ask for the state without driving the motor (a disabled or faulted motor is polled
        with these, so its state is still published)."""

    @abstractmethod
    def command_frames(self, cmd: ImpedanceCommand, last: Feedback | None) -> list[Frame]: ...

    @property
    @abstractmethod
    def device_id(self) -> int:
        """The id this device answers with (what :meth:`sender` returns for its frames)."""

    @abstractmethod
    def sender(self, frame: Frame) -> int | None:
        """Which device of this protocol sent ``frame`` (None: not a device's frame). Lets a
        bus of several motors route a frame to its motor without trying every decoder."""

    @abstractmethod
    def decode(self, frame: Frame) -> Feedback | None:
        """A complete sample from this actuator, None for frames that are not (or not yet) one.

        Raises :class:`MalformedFrameError` for a frame addressed as ours that the protocol does
        not allow.
        """


# --------------------------------------------------------------------------- MIT mode


class MitProtocol(ActuatorProtocol):
    name = "mit"

    def __init__(
        self,
        motor_id: int = 1,
        limits: mit.MitLimits | None = None,
        *,
        master_id: int = 0,
        gear_ratio: float = 1.0,
    ) -> None:
        super().__init__(gear_ratio)
        if not 0 < motor_id <= 0x7FF:
            raise CanProtocolError(f"MIT motor id must be 1..0x7ff, got {motor_id}")
        self.motor_id = motor_id
        self.master_id = master_id
        self.limits = limits or mit.MitLimits()

    def _frame(self, data: bytes) -> Frame:
        return Frame(self.motor_id, data)

    def enable_frames(self) -> list[Frame]:
        return [self._frame(mit.ENTER_MOTOR_MODE)]

    def disable_frames(self) -> list[Frame]:
        return [self._command(ImpedanceCommand.zero_torque()), self._frame(mit.EXIT_MOTOR_MODE)]

    def zero_frames(self, last: Feedback | None) -> list[Frame]:
        return [self._frame(mit.SET_ZERO)]

    def query_frames(self) -> list[Frame]:
        return [self._frame(mit.EXIT_MOTOR_MODE)]  # answered with the state; stays released

    def _command(self, cmd: ImpedanceCommand) -> Frame:
        g = self.gear_ratio
        native = mit.MitCommand(
            position_rad=cmd.position_rad * g,
            velocity_rad_s=cmd.velocity_rad_s * g,
            kp=cmd.kp_nm_per_rad / (g * g),
            kd=cmd.kd_nms_per_rad / (g * g),
            torque_nm=cmd.torque_ff_nm / g,
        )
        return self._frame(mit.encode_command(native, self.limits))

    def command_frames(self, cmd: ImpedanceCommand, last: Feedback | None) -> list[Frame]:
        return [self._command(cmd)]

    @property
    def device_id(self) -> int:
        return self.motor_id & 0xFF

    def sender(self, frame: Frame) -> int | None:
        if frame.arbitration_id != self.master_id or frame.is_remote or not frame.data:
            return None
        return frame.data[0]

    def decode(self, frame: Frame) -> Feedback | None:
        if frame.arbitration_id != self.master_id or frame.is_remote or not frame.data:
            return None
        if frame.data[0] != self.motor_id & 0xFF:
            return None
        reply = mit.decode_reply(frame.data, self.limits)
        g = self.gear_ratio
        return Feedback(reply.position_rad / g, reply.velocity_rad_s / g, reply.torque_nm * g)


# --------------------------------------------------------------------------- ODrive CANSimple


class ODriveProtocol(ActuatorProtocol):
    name = "odrive"

    def __init__(self, node_id: int = 0, *, gear_ratio: float = 1.0) -> None:
        super().__init__(gear_ratio)
        odrive.arbitration_id(node_id, 0)  # validates the id
        self.node_id = node_id
        self._torque_estimate_nm = 0.0
        self.last_heartbeat: odrive.Heartbeat | None = None

    def _id(self, cmd: odrive.Cmd) -> int:
        return odrive.arbitration_id(self.node_id, cmd)

    def enable_frames(self) -> list[Frame]:
        mode = odrive.encode_set_controller_mode(
            odrive.ControlMode.TORQUE, odrive.InputMode.PASSTHROUGH
        )
        return [
            Frame(self._id(odrive.Cmd.SET_CONTROLLER_MODE), mode),
            Frame(self._id(odrive.Cmd.SET_INPUT_TORQUE), odrive.encode_set_input_torque(0.0)),
            Frame(
                self._id(odrive.Cmd.SET_AXIS_STATE),
                odrive.encode_set_axis_state(odrive.AxisState.CLOSED_LOOP_CONTROL),
            ),
            *self._requests(),
        ]

    def disable_frames(self) -> list[Frame]:
        return [
            Frame(self._id(odrive.Cmd.SET_INPUT_TORQUE), odrive.encode_set_input_torque(0.0)),
            Frame(
                self._id(odrive.Cmd.SET_AXIS_STATE),
                odrive.encode_set_axis_state(odrive.AxisState.IDLE),
            ),
            *self._requests(),
        ]

    def zero_frames(self, last: Feedback | None) -> list[Frame]:
        if last is not None:
            self.zero_offset_rad += last.position_rad
        return self._requests()

    def query_frames(self) -> list[Frame]:
        return self._requests()

    def _requests(self) -> list[Frame]:
        return [
            Frame(self._id(odrive.Cmd.GET_TORQUES), b"", is_remote=True),
            Frame(self._id(odrive.Cmd.GET_ENCODER_ESTIMATES), b"", is_remote=True),
        ]

    def command_frames(self, cmd: ImpedanceCommand, last: Feedback | None) -> list[Frame]:
        torque = cmd.torque_ff_nm
        if last is not None:
            torque += cmd.kp_nm_per_rad * (cmd.position_rad - last.position_rad)
            torque += cmd.kd_nms_per_rad * (cmd.velocity_rad_s - last.velocity_rad_s)
        native = odrive.encode_set_input_torque(torque / self.gear_ratio)
        return [Frame(self._id(odrive.Cmd.SET_INPUT_TORQUE), native), *self._requests()]

    @property
    def device_id(self) -> int:
        return self.node_id

    def sender(self, frame: Frame) -> int | None:
        if frame.is_remote or frame.arbitration_id > 0x7FF:
            return None
        return frame.arbitration_id >> 5

    def decode(self, frame: Frame) -> Feedback | None:
        if frame.is_remote or frame.arbitration_id > 0x7FF:
            return None
        node, cmd = odrive.split_id(frame.arbitration_id)
        if node != self.node_id:
            return None
        g = self.gear_ratio
        if cmd == odrive.Cmd.HEARTBEAT:
            self.last_heartbeat = odrive.decode_heartbeat(frame.data)
        elif cmd == odrive.Cmd.GET_TORQUES:
            self._torque_estimate_nm = odrive.decode_torques(frame.data).estimate_nm * g
        elif cmd == odrive.Cmd.GET_ENCODER_ESTIMATES:
            est = odrive.decode_encoder_estimates(frame.data)
            return Feedback(
                est.position_rev * TWO_PI / g - self.zero_offset_rad,
                est.velocity_rev_s * TWO_PI / g,
                self._torque_estimate_nm,
            )
        return None


# --------------------------------------------------------------------------- moteus


class MoteusProtocol(ActuatorProtocol):
    """moteus over CAN-FD. ``kp_nm_per_rev``/``kd_nms_per_rev`` are the gains configured in the
    controller (servo.pid_position.kp, .kd); commands send fractions (scales) of them."""

    name = "moteus"
    is_fd = True

    def __init__(
        self,
        device_id: int = 1,
        *,
        source_id: int = 0,
        kp_nm_per_rev: float = 200.0,
        kd_nms_per_rev: float = 5.0,
        watchdog_timeout_s: float = 0.1,
        gear_ratio: float = 1.0,
    ) -> None:
        super().__init__(gear_ratio)
        moteus_fd.arbitration_id(source_id, device_id, reply=True)  # validates the ids
        if not (kp_nm_per_rev > 0 and kd_nms_per_rev > 0 and watchdog_timeout_s > 0):
            raise CanProtocolError("moteus kp, kd and watchdog timeout must be > 0")
        self.device_id = device_id
        self.source_id = source_id
        self.kp_nm_per_rev = kp_nm_per_rev
        self.kd_nms_per_rev = kd_nms_per_rev
        self.watchdog_timeout_s = watchdog_timeout_s

    def _frame(self, payload: bytes) -> Frame:
        arb = moteus_fd.arbitration_id(self.source_id, self.device_id, reply=True)
        return Frame(arb, moteus_fd.pad_fd(payload), is_fd=True, is_extended_id=True)

    def enable_frames(self) -> list[Frame]:
        return [self._frame(moteus_fd.stop_command(moteus_fd.DEFAULT_QUERY))]

    def disable_frames(self) -> list[Frame]:
        return [self._frame(moteus_fd.stop_command(moteus_fd.DEFAULT_QUERY))]

    def zero_frames(self, last: Feedback | None) -> list[Frame]:
        if last is not None:
            self.zero_offset_rad += last.position_rad
        return [self._frame(moteus_fd.encode_query(moteus_fd.DEFAULT_QUERY))]

    def query_frames(self) -> list[Frame]:
        return [self._frame(moteus_fd.encode_query(moteus_fd.DEFAULT_QUERY))]

    def kp_scale(self, kp_nm_per_rad: float) -> float:
        """Output-side stiffness as a fraction of the configured kp (which is per motor rev)."""
        return kp_nm_per_rad * TWO_PI / (self.gear_ratio**2 * self.kp_nm_per_rev)

    def kd_scale(self, kd_nms_per_rad: float) -> float:
        return kd_nms_per_rad * TWO_PI / (self.gear_ratio**2 * self.kd_nms_per_rev)

    def command_frames(self, cmd: ImpedanceCommand, last: Feedback | None) -> list[Frame]:
        g = self.gear_ratio
        payload = moteus_fd.position_command(
            position_rev=(cmd.position_rad + self.zero_offset_rad) * g / TWO_PI,
            velocity_rev_s=cmd.velocity_rad_s * g / TWO_PI,
            feedforward_torque_nm=cmd.torque_ff_nm / g,
            kp_scale=self.kp_scale(cmd.kp_nm_per_rad),
            kd_scale=self.kd_scale(cmd.kd_nms_per_rad),
            watchdog_timeout_s=self.watchdog_timeout_s,
            query=moteus_fd.DEFAULT_QUERY,
        )
        return [self._frame(payload)]

    @property
    def device_id(self) -> int:
        return self._device_id

    @device_id.setter
    def device_id(self, value: int) -> None:
        self._device_id = value

    def sender(self, frame: Frame) -> int | None:
        source, destination, _ = moteus_fd.split_id(frame.arbitration_id)
        return None if destination != self.source_id or frame.is_remote else source

    def decode(self, frame: Frame) -> Feedback | None:
        source, destination, _ = moteus_fd.split_id(frame.arbitration_id)
        if source != self.device_id or destination != self.source_id or frame.is_remote:
            return None
        values = moteus_fd.parse_values(frame.data, moteus_fd.REPLY)
        needed = (moteus_fd.Reg.POSITION, moteus_fd.Reg.VELOCITY, moteus_fd.Reg.TORQUE)
        if any(r not in values for r in needed):
            raise MalformedFrameError("moteus reply lacks position, velocity or torque")
        g = self.gear_ratio
        return Feedback(
            float(values[moteus_fd.Reg.POSITION]) * TWO_PI / g - self.zero_offset_rad,
            float(values[moteus_fd.Reg.VELOCITY]) * TWO_PI / g,
            float(values[moteus_fd.Reg.TORQUE]) * g,
            moteus_fd.mode_fault(values),
        )


PROTOCOLS = ("mit", "odrive", "moteus")
