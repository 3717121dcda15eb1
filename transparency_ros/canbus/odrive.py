"""ODrive CANSimple (firmware 0.6): arbitration id = node_id << 5 | cmd_id, little-endian payloads.

Only the messages the driver uses are implemented. Units are ODrive's: turns [rev], rev/s, N m.

0x01 Heartbeat (ODrive->host): axis_error u32, axis_state u8, procedure_result u8,
     trajectory_done u8 (bit 0)
0x07 Set_Axis_State (host->ODrive): requested_state u32
0x09 Get_Encoder_Estimates (ODrive->host, or on an RTR request): pos f32 [rev], vel f32 [rev/s]
0x0B Set_Controller_Mode (host->ODrive): control_mode u32, input_mode u32
0x0C Set_Input_Pos (host->ODrive): pos f32 [rev], vel_ff i16 [1e-3 rev/s], torque_ff i16 [1e-3 N m]
0x0E Set_Input_Torque (host->ODrive): torque f32 [N m]
0x1C Get_Torques (ODrive->host, or on an RTR request): target f32, estimate f32 [N m]
"""

from __future__ import annotations

import math
import struct
from enum import IntEnum
from typing import Any, NamedTuple

from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError

MAX_NODE_ID = 0x3F


class Cmd(IntEnum):
    HEARTBEAT = 0x01
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_POS = 0x0C
    SET_INPUT_TORQUE = 0x0E
    GET_TORQUES = 0x1C


class AxisState(IntEnum):
    UNDEFINED = 0
    IDLE = 1
    CLOSED_LOOP_CONTROL = 8


class ControlMode(IntEnum):
    VOLTAGE = 0
    TORQUE = 1
    VELOCITY = 2
    POSITION = 3


class InputMode(IntEnum):
    INACTIVE = 0
    PASSTHROUGH = 1


class Heartbeat(NamedTuple):
    axis_error: int
    axis_state: int
    procedure_result: int
    trajectory_done: bool


class EncoderEstimates(NamedTuple):
    position_rev: float
    velocity_rev_s: float


class Torques(NamedTuple):
    target_nm: float
    estimate_nm: float


class InputPos(NamedTuple):
    position_rev: float
    velocity_ff_rev_s: float
    torque_ff_nm: float


_U32 = struct.Struct("<I")
_U32_U32 = struct.Struct("<II")
_F32 = struct.Struct("<f")
_F32_F32 = struct.Struct("<ff")
_HEARTBEAT = struct.Struct("<IBBB")
_INPUT_POS = struct.Struct("<fhh")
_FF_SCALE = 1e-3


def arbitration_id(node_id: int, cmd: int) -> int:
    if not 0 <= node_id <= MAX_NODE_ID:
        raise CanProtocolError(f"ODrive node id must be 0..{MAX_NODE_ID}, got {node_id}")
    return (node_id << 5) | (cmd & 0x1F)


def split_id(arb_id: int) -> tuple[int, int]:
    """(node_id, cmd_id) of a CANSimple arbitration id."""
    if not 0 <= arb_id <= 0x7FF:
        raise MalformedFrameError(f"CANSimple uses 11-bit ids, got 0x{arb_id:x}")
    return arb_id >> 5, arb_id & 0x1F


def _finite(*values: float) -> None:
    for value in values:
        if not math.isfinite(value):
            raise CanProtocolError(f"cannot encode non-finite value {value!r}")


def _payload(data: bytes, layout: struct.Struct, name: str) -> tuple[Any, ...]:
    if len(data) < layout.size:
        raise MalformedFrameError(
            f"ODrive {name}: expected >= {layout.size} bytes, got {len(data)}"
        )
    return layout.unpack_from(bytes(data))


def _pad8(payload: bytes) -> bytes:
    return payload + bytes(8 - len(payload))


def encode_set_axis_state(state: int) -> bytes:
    return _pad8(_U32.pack(state))


def decode_set_axis_state(data: bytes) -> int:
    (state,) = _payload(data, _U32, "Set_Axis_State")
    return int(state)


def encode_set_controller_mode(control_mode: int, input_mode: int) -> bytes:
    return _U32_U32.pack(control_mode, input_mode)


def decode_set_controller_mode(data: bytes) -> tuple[int, int]:
    control, inp = _payload(data, _U32_U32, "Set_Controller_Mode")
    return int(control), int(inp)


def encode_set_input_torque(torque_nm: float) -> bytes:
    _finite(torque_nm)
    return _pad8(_F32.pack(torque_nm))


def decode_set_input_torque(data: bytes) -> float:
    (torque,) = _payload(data, _F32, "Set_Input_Torque")
    return float(torque)


def _ff_int(value: float, name: str) -> int:
    raw = round(value / _FF_SCALE)
    if not -0x8000 <= raw <= 0x7FFF:
        raise CanProtocolError(f"ODrive {name} {value} outside the int16 range of 1e-3 units")
    return raw


def encode_set_input_pos(cmd: InputPos) -> bytes:
    _finite(*cmd)
    return _INPUT_POS.pack(
        cmd.position_rev,
        _ff_int(cmd.velocity_ff_rev_s, "vel_ff"),
        _ff_int(cmd.torque_ff_nm, "torque_ff"),
    )


def decode_set_input_pos(data: bytes) -> InputPos:
    pos, vel, torque = _payload(data, _INPUT_POS, "Set_Input_Pos")
    return InputPos(float(pos), int(vel) * _FF_SCALE, int(torque) * _FF_SCALE)


def encode_heartbeat(hb: Heartbeat) -> bytes:
    return _pad8(
        _HEARTBEAT.pack(
            hb.axis_error, hb.axis_state, hb.procedure_result, 1 if hb.trajectory_done else 0
        )
    )


def decode_heartbeat(data: bytes) -> Heartbeat:
    error, state, result, done = _payload(data, _HEARTBEAT, "Heartbeat")
    return Heartbeat(int(error), int(state), int(result), bool(int(done) & 1))


def encode_encoder_estimates(est: EncoderEstimates) -> bytes:
    return _F32_F32.pack(est.position_rev, est.velocity_rev_s)


def decode_encoder_estimates(data: bytes) -> EncoderEstimates:
    pos, vel = _payload(data, _F32_F32, "Get_Encoder_Estimates")
    return EncoderEstimates(float(pos), float(vel))


def encode_torques(torques: Torques) -> bytes:
    return _F32_F32.pack(torques.target_nm, torques.estimate_nm)


def decode_torques(data: bytes) -> Torques:
    target, estimate = _payload(data, _F32_F32, "Get_Torques")
    return Torques(float(target), float(estimate))
