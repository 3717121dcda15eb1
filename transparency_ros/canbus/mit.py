"""MIT mode: the mini-cheetah / T-Motor AK series CAN protocol (classic CAN, 1 Mbit/s).

Host -> motor, 8 bytes, big-endian bit packing:   p:16 v:12 kp:12 kd:12 t:12
Motor -> host, 6 bytes:                            id:8 p:16 v:12 t:12
               8 bytes (AK firmware variant):      ... + temperature:8 error:8
Special frames (8 bytes): FF FF FF FF FF FF FF FC enter motor mode, ...FD exit, ...FE set zero.

Every quantity is mapped linearly onto an unsigned integer of n bits with the firmware's
``float_to_uint``: ``int((x - x_min) * (2^n - 1) / (x_max - x_min))`` after clamping x to the
range. The ranges differ between motors and firmware versions (AK80-6 v1.1: P +-12.5 rad,
V +-22.5 rad/s, T +-12 N m; v1.0: P +-95.5 rad ...), so they are configuration, never constants:
:class:`MitLimits`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError

ENTER_MOTOR_MODE = bytes([0xFF] * 7 + [0xFC])
EXIT_MOTOR_MODE = bytes([0xFF] * 7 + [0xFD])
SET_ZERO = bytes([0xFF] * 7 + [0xFE])
SPECIAL_FRAMES = {ENTER_MOTOR_MODE: "enter", EXIT_MOTOR_MODE: "exit", SET_ZERO: "zero"}

POSITION_BITS, VELOCITY_BITS, GAIN_BITS, TORQUE_BITS = 16, 12, 12, 12


@dataclass(frozen=True)
class MitLimits:
    """Ranges of the integer mapping. Defaults: T-Motor AK80-6, firmware v1.1."""

    p_min_rad: float = -12.5
    p_max_rad: float = 12.5
    v_min_rad_s: float = -22.5
    v_max_rad_s: float = 22.5
    kp_min: float = 0.0
    kp_max: float = 500.0
    kd_min: float = 0.0
    kd_max: float = 5.0
    t_min_nm: float = -12.0
    t_max_nm: float = 12.0

    def __post_init__(self) -> None:
        pairs = (
            ("p", self.p_min_rad, self.p_max_rad),
            ("v", self.v_min_rad_s, self.v_max_rad_s),
            ("kp", self.kp_min, self.kp_max),
            ("kd", self.kd_min, self.kd_max),
            ("t", self.t_min_nm, self.t_max_nm),
        )
        for name, low, high in pairs:
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise CanProtocolError(
                    f"MIT limits: {name} range must satisfy min < max, got [{low}, {high}]"
                )


class MitCommand(NamedTuple):
    position_rad: float
    velocity_rad_s: float
    kp: float  # N m / rad
    kd: float  # N m s / rad
    torque_nm: float  # feed-forward


class MitReply(NamedTuple):
    motor_id: int
    position_rad: float
    velocity_rad_s: float
    torque_nm: float
    temperature_raw: int | None  # AK 8-byte variant only; the offset to deg C varies by firmware
    error_code: int | None


def float_to_uint(x: float, x_min: float, x_max: float, bits: int) -> int:
    """The firmware's mapping, after clamping x into [x_min, x_max]."""
    if not math.isfinite(x):
        raise CanProtocolError(f"cannot encode non-finite value {x!r}")
    clamped = min(max(x, x_min), x_max)
    return int(((clamped - x_min) * ((1 << bits) - 1)) / (x_max - x_min))


def uint_to_float(x_int: int, x_min: float, x_max: float, bits: int) -> float:
    return ((x_int * (x_max - x_min)) / ((1 << bits) - 1)) + x_min


def encode_command(cmd: MitCommand, limits: MitLimits) -> bytes:
    p = float_to_uint(cmd.position_rad, limits.p_min_rad, limits.p_max_rad, POSITION_BITS)
    v = float_to_uint(cmd.velocity_rad_s, limits.v_min_rad_s, limits.v_max_rad_s, VELOCITY_BITS)
    kp = float_to_uint(cmd.kp, limits.kp_min, limits.kp_max, GAIN_BITS)
    kd = float_to_uint(cmd.kd, limits.kd_min, limits.kd_max, GAIN_BITS)
    t = float_to_uint(cmd.torque_nm, limits.t_min_nm, limits.t_max_nm, TORQUE_BITS)
    return bytes([
        p >> 8, p & 0xFF,
        v >> 4, ((v & 0xF) << 4) | (kp >> 8), kp & 0xFF,
        kd >> 4, ((kd & 0xF) << 4) | (t >> 8), t & 0xFF,
    ])  # fmt: skip


def decode_command(data: bytes, limits: MitLimits) -> MitCommand:
    """What the firmware does with a command frame (used by the simulated motor)."""
    if len(data) != 8:
        raise MalformedFrameError(f"MIT command must be 8 bytes, got {len(data)}")
    if bytes(data) in SPECIAL_FRAMES:
        raise MalformedFrameError("special frame, not a command")
    p = (data[0] << 8) | data[1]
    v = (data[2] << 4) | (data[3] >> 4)
    kp = ((data[3] & 0xF) << 8) | data[4]
    kd = (data[5] << 4) | (data[6] >> 4)
    t = ((data[6] & 0xF) << 8) | data[7]
    return MitCommand(
        uint_to_float(p, limits.p_min_rad, limits.p_max_rad, POSITION_BITS),
        uint_to_float(v, limits.v_min_rad_s, limits.v_max_rad_s, VELOCITY_BITS),
        uint_to_float(kp, limits.kp_min, limits.kp_max, GAIN_BITS),
        uint_to_float(kd, limits.kd_min, limits.kd_max, GAIN_BITS),
        uint_to_float(t, limits.t_min_nm, limits.t_max_nm, TORQUE_BITS),
    )


def encode_reply(
    motor_id: int,
    position_rad: float,
    velocity_rad_s: float,
    torque_nm: float,
    limits: MitLimits,
    *,
    temperature_raw: int | None = None,
    error_code: int | None = None,
) -> bytes:
    """A motor's status reply: 6 bytes, or 8 with the AK temperature and error code."""
    if not 0 <= motor_id <= 0xFF:
        raise CanProtocolError(f"motor id must fit one byte, got {motor_id}")
    p = float_to_uint(position_rad, limits.p_min_rad, limits.p_max_rad, POSITION_BITS)
    v = float_to_uint(velocity_rad_s, limits.v_min_rad_s, limits.v_max_rad_s, VELOCITY_BITS)
    t = float_to_uint(torque_nm, limits.t_min_nm, limits.t_max_nm, TORQUE_BITS)
    frame = bytes([motor_id, p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF])
    if temperature_raw is None and error_code is None:
        return frame
    temperature = 0 if temperature_raw is None else temperature_raw
    error = 0 if error_code is None else error_code
    if not (0 <= temperature <= 0xFF and 0 <= error <= 0xFF):
        raise CanProtocolError("temperature and error code must fit one byte each")
    return frame + bytes([temperature, error])


def decode_reply(data: bytes, limits: MitLimits) -> MitReply:
    if len(data) not in (6, 8):
        raise MalformedFrameError(f"MIT reply must be 6 or 8 bytes, got {len(data)}")
    p = (data[1] << 8) | data[2]
    v = (data[3] << 4) | (data[4] >> 4)
    t = ((data[4] & 0xF) << 8) | data[5]
    return MitReply(
        motor_id=data[0],
        position_rad=uint_to_float(p, limits.p_min_rad, limits.p_max_rad, POSITION_BITS),
        velocity_rad_s=uint_to_float(v, limits.v_min_rad_s, limits.v_max_rad_s, VELOCITY_BITS),
        torque_nm=uint_to_float(t, limits.t_min_nm, limits.t_max_nm, TORQUE_BITS),
        temperature_raw=data[6] if len(data) == 8 else None,
        error_code=data[7] if len(data) == 8 else None,
    )
