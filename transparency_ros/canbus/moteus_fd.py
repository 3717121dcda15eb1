"""mjbots moteus register protocol over CAN-FD ("multiplex" framing).

Arbitration id: 0x8000 when a reply is requested | source << 8 | destination.
A frame is a sequence of subframes. The first byte of each names the operation and type:

    0x00 write, 0x10 read, 0x20 reply;  + type << 2 (int8 0, int16 1, int32 2, f32 3);
    + count in the low two bits (1-3), or 0 and then a varuint count;
    then the start register as a varuint, then (write, reply) count little-endian values.
    0x30 write error / 0x31 read error: varuint register, varuint error code.
    0x50 NOP: padding up to a valid CAN-FD length.

Integer types are scaled per register kind (position: 0.01, 1e-4, 1e-5 rev for int8/16/32, ...);
the most negative integer of each type means NaN ("no value"). Units are moteus's own: rev,
rev/s, N m, s; kp/kd scales are fractions of the gains configured in the controller.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping
from enum import IntEnum
from typing import NamedTuple

from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError


class Res(IntEnum):
    INT8 = 0
    INT16 = 1
    INT32 = 2
    F32 = 3


class Reg(IntEnum):
    MODE = 0x000
    POSITION = 0x001
    VELOCITY = 0x002
    TORQUE = 0x003
    VOLTAGE = 0x00D
    TEMPERATURE = 0x00E
    FAULT = 0x00F
    COMMAND_POSITION = 0x020
    COMMAND_VELOCITY = 0x021
    COMMAND_FEEDFORWARD_TORQUE = 0x022
    COMMAND_KP_SCALE = 0x023
    COMMAND_KD_SCALE = 0x024
    COMMAND_MAX_TORQUE = 0x025
    COMMAND_STOP_POSITION = 0x026
    COMMAND_TIMEOUT = 0x027


class Mode(IntEnum):
    STOPPED = 0
    FAULT = 1
    POSITION = 10
    TIMEOUT = 11


def mode_fault(values: Mapping[int, float]) -> str:
    """What a reply's mode says stops the controller driving ("": nothing, or no mode read):
    a fault (with its code) or the position watchdog's timeout, both latched until a stop
    command (moteus reference: a controller not commanded within its watchdog's time enters
    the timeout mode and stays there)."""
    mode = values.get(Reg.MODE)
    if mode is None or math.isnan(mode):
        return ""
    if int(mode) == Mode.FAULT:
        code = values.get(Reg.FAULT, math.nan)
        return f"moteus fault (code {'?' if math.isnan(code) else int(code)})"
    if int(mode) == Mode.TIMEOUT:
        return "moteus position timeout: no command within its watchdog time (latched)"
    return ""


WRITE, READ, REPLY = 0x00, 0x10, 0x20
WRITE_ERROR, READ_ERROR, NOP = 0x30, 0x31, 0x50
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
REPLY_FLAG = 0x8000

_TYPES = {
    Res.INT8: struct.Struct("<b"),
    Res.INT16: struct.Struct("<h"),
    Res.INT32: struct.Struct("<i"),
    Res.F32: struct.Struct("<f"),
}
_INT_MAX = {Res.INT8: 127, Res.INT16: 32767, Res.INT32: 2147483647}
_INT_NAN = {Res.INT8: -128, Res.INT16: -32768, Res.INT32: -2147483648}

# Scale of one integer unit for int8, int16, int32, per register kind.
_POSITION = (0.01, 0.0001, 0.00001)
_VELOCITY = (0.1, 0.00025, 0.00001)
_TORQUE = (0.5, 0.01, 0.001)
_SCALE = (1.0 / 127.0, 1.0 / 32767.0, 1.0 / 2147483647.0)
_TIME = (0.01, 0.001, 0.000001)
_VOLTAGE = (0.5, 0.1, 0.001)
_TEMPERATURE = (1.0, 0.1, 0.001)
_INTEGER = (1.0, 1.0, 1.0)
REGISTER_SCALES: dict[int, tuple[float, float, float]] = {
    Reg.MODE: _INTEGER,
    Reg.POSITION: _POSITION,
    Reg.VELOCITY: _VELOCITY,
    Reg.TORQUE: _TORQUE,
    Reg.VOLTAGE: _VOLTAGE,
    Reg.TEMPERATURE: _TEMPERATURE,
    Reg.FAULT: _INTEGER,
    Reg.COMMAND_POSITION: _POSITION,
    Reg.COMMAND_VELOCITY: _VELOCITY,
    Reg.COMMAND_FEEDFORWARD_TORQUE: _TORQUE,
    Reg.COMMAND_KP_SCALE: _SCALE,
    Reg.COMMAND_KD_SCALE: _SCALE,
    Reg.COMMAND_MAX_TORQUE: _TORQUE,
    Reg.COMMAND_STOP_POSITION: _POSITION,
    Reg.COMMAND_TIMEOUT: _TIME,
}
INTEGER_REGISTERS = frozenset({Reg.MODE, Reg.FAULT})

# What the driver asks for with every command (the moteus library's default query).
DEFAULT_QUERY: dict[int, Res] = {
    Reg.MODE: Res.INT8,
    Reg.POSITION: Res.F32,
    Reg.VELOCITY: Res.F32,
    Reg.TORQUE: Res.F32,
    Reg.VOLTAGE: Res.INT8,
    Reg.TEMPERATURE: Res.INT8,
    Reg.FAULT: Res.INT8,
}


class Subframe(NamedTuple):
    """One decoded subframe: op is WRITE, READ, REPLY, WRITE_ERROR or READ_ERROR."""

    op: int
    register: int
    resolution: Res | None
    value: float | int | None  # scaled (None for READ); error code for *_ERROR


# --------------------------------------------------------------------------- ids


def arbitration_id(source: int, destination: int, *, reply: bool, prefix: int = 0) -> int:
    for name, value in (("source", source), ("destination", destination)):
        if not 0 <= value <= 0x7F:
            raise CanProtocolError(f"moteus {name} id must be 0..127, got {value}")
    return (prefix << 16) | (REPLY_FLAG if reply else 0) | (source << 8) | destination


def split_id(arb_id: int) -> tuple[int, int, bool]:
    """(source, destination, reply_requested)."""
    return (arb_id >> 8) & 0x7F, arb_id & 0x7F, bool(arb_id & REPLY_FLAG)


# --------------------------------------------------------------------------- scalar mapping


def to_raw(register: int, value: float, resolution: Res) -> float | int:
    """Physical value -> the number stored in the frame (saturated; NaN as the type minimum)."""
    if resolution is Res.F32:
        return value
    if not math.isfinite(value):
        return _INT_NAN[resolution]
    scale = REGISTER_SCALES.get(register, _INTEGER)[resolution]
    scaled = value / scale
    limit = _INT_MAX[resolution]
    return int(max(-limit, min(limit, scaled)))


def from_raw(register: int, raw: float | int, resolution: Res) -> float | int:
    if resolution is Res.F32:
        return float(raw)
    if raw == _INT_NAN[resolution]:
        return math.nan
    if register in INTEGER_REGISTERS:
        return int(raw)
    return raw * REGISTER_SCALES.get(register, _INTEGER)[resolution]


# --------------------------------------------------------------------------- encoding


def _varuint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _runs(items: Iterable[tuple[int, Res]]) -> list[tuple[int, Res, int]]:
    """Group (register, resolution) into runs of consecutive registers of one resolution."""
    runs: list[tuple[int, Res, int]] = []
    for register, resolution in sorted(items):
        if runs:
            start, res, count = runs[-1]
            if res is resolution and register == start + count:
                runs[-1] = (start, res, count + 1)
                continue
        runs.append((register, resolution, 1))
    return runs


def _header(op: int, resolution: Res, count: int, start: int) -> bytes:
    base = op | (int(resolution) << 2)
    prefix = bytes([base + count]) if count <= 3 else bytes([base, count])
    return prefix + _varuint(start)


def encode_values(op: int, values: Mapping[int, tuple[float, Res]]) -> bytes:
    """WRITE or REPLY subframes for {register: (physical value, resolution)}."""
    if op not in (WRITE, REPLY):
        raise CanProtocolError(f"encode_values takes WRITE or REPLY, got 0x{op:02x}")
    out = bytearray()
    for start, resolution, count in _runs((r, res) for r, (_, res) in values.items()):
        out += _header(op, resolution, count, start)
        for register in range(start, start + count):
            raw = to_raw(register, values[register][0], resolution)
            out += _TYPES[resolution].pack(raw)
    return bytes(out)


def encode_query(registers: Mapping[int, Res]) -> bytes:
    out = bytearray()
    for start, resolution, count in _runs(registers.items()):
        out += _header(READ, resolution, count, start)
    return bytes(out)


def pad_fd(payload: bytes) -> bytes:
    """Pad with NOP bytes to the next valid CAN-FD data length."""
    if len(payload) > 64:
        raise CanProtocolError(f"moteus frame of {len(payload)} bytes exceeds CAN-FD's 64")
    target = next(n for n in FD_LENGTHS if n >= len(payload))
    return payload + bytes([NOP]) * (target - len(payload))


def position_command(
    *,
    position_rev: float,
    velocity_rev_s: float,
    feedforward_torque_nm: float,
    kp_scale: float,
    kd_scale: float,
    watchdog_timeout_s: float,
    resolution: Res = Res.F32,
    query: Mapping[int, Res] | None = None,
) -> bytes:
    """Position mode with the impedance terms, optionally followed by a query (unpadded)."""
    frame = encode_values(WRITE, {Reg.MODE: (Mode.POSITION, Res.INT8)})
    frame += encode_values(WRITE, {
        Reg.COMMAND_POSITION: (position_rev, resolution),
        Reg.COMMAND_VELOCITY: (velocity_rev_s, resolution),
        Reg.COMMAND_FEEDFORWARD_TORQUE: (feedforward_torque_nm, resolution),
        Reg.COMMAND_KP_SCALE: (kp_scale, resolution),
        Reg.COMMAND_KD_SCALE: (kd_scale, resolution),
        Reg.COMMAND_TIMEOUT: (watchdog_timeout_s, resolution),
    })  # fmt: skip
    return frame + (encode_query(query) if query else b"")


def stop_command(query: Mapping[int, Res] | None = None) -> bytes:
    frame = encode_values(WRITE, {Reg.MODE: (Mode.STOPPED, Res.INT8)})
    return frame + (encode_query(query) if query else b"")


# --------------------------------------------------------------------------- decoding


# a READ subframe names registers without values: its count is not bounded by the frame's
# length, but the reply to it must fit one CAN-FD frame (64 bytes, a byte or more a register)
MAX_READ_COUNT = 64


class _Reader:
    def __init__(self, data: bytes) -> None:
        self.data = bytes(data)
        self.pos = 0

    def remaining(self) -> int:
        return len(self.data) - self.pos

    def byte(self) -> int:
        if self.pos >= len(self.data):
            raise MalformedFrameError("moteus frame ends inside a subframe")
        value = self.data[self.pos]
        self.pos += 1
        return value

    def varuint(self) -> int:
        value, shift = 0, 0
        for _ in range(5):
            byte = self.byte()
            value |= (byte & 0x7F) << shift
            if not byte & 0x80:
                return value
            shift += 7
        raise MalformedFrameError("moteus varuint longer than 5 bytes")

    def value(self, resolution: Res) -> float | int:
        layout = _TYPES[resolution]
        if self.remaining() < layout.size:
            raise MalformedFrameError("moteus frame ends inside a value")
        (raw,) = layout.unpack_from(self.data, self.pos)
        self.pos += layout.size
        return raw  # type: ignore[no-any-return]


def parse_frame(data: bytes) -> list[Subframe]:
    """Every subframe of a frame, values scaled to physical units."""
    reader = _Reader(data)
    subframes: list[Subframe] = []
    while reader.remaining():
        head = reader.byte()
        if head == NOP:
            continue
        if head in (WRITE_ERROR, READ_ERROR):
            register = reader.varuint()
            subframes.append(Subframe(head, register, None, reader.varuint()))
            continue
        op = head & 0xF0
        if op not in (WRITE, READ, REPLY):
            raise MalformedFrameError(f"moteus subframe type 0x{head:02x} at byte {reader.pos - 1}")
        resolution = Res((head >> 2) & 0x3)
        count = head & 0x3 or reader.varuint()
        start = reader.varuint()
        if op == READ and count > MAX_READ_COUNT:  # (values bound themselves: a byte or more)
            raise MalformedFrameError(
                f"moteus read of {count} registers at byte {reader.pos}: no reply frame holds them"
            )
        for register in range(start, start + count):
            if op == READ:
                subframes.append(Subframe(op, register, resolution, None))
            else:
                raw = reader.value(resolution)
                subframes.append(
                    Subframe(op, register, resolution, from_raw(register, raw, resolution))
                )
    return subframes


def parse_values(data: bytes, op: int) -> dict[int, float | int]:
    """{register: value} of every subframe of type ``op`` (WRITE or REPLY) in a frame."""
    return {s.register: s.value for s in parse_frame(data) if s.op == op and s.value is not None}
