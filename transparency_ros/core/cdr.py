"""CDR for the messages on the estimator's hot path, without rclpy's message objects.

rclpy turns every received message into a Python object and every published one back into C
structures; for a ``sensor_msgs/JointState`` that is about 20 us each way on the benchmark
machine, a fifth of the time a sample may take at 10 kHz. The estimator therefore takes
``/joint_states`` as serialized bytes (``raw=True``) and publishes bytes built here.

Format: the OMG CDR that ROS 2 uses (XCDR1), little endian (encapsulation ``00 01 00 00``);
after the 4-byte encapsulation header every primitive is aligned to its size, counted from the
first byte after the header; strings are a uint32 length including the terminating NUL, then
the bytes; sequences are a uint32 count, then the elements (aligned to the element's size only
when there is at least one element). Anything else (big endian, other encapsulations) is
refused with :class:`CdrError` and left to rclpy's deserializer.

``test/unit/test_cdr.py`` checks, with hypothesis, that these bytes and rclpy's own serializer
agree both ways.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from transparency_ros.core import stamps
from transparency_ros.core.errors import TransparencyError

LITTLE_ENDIAN_CDR = b"\x00\x01\x00\x00"
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


class CdrError(TransparencyError, ValueError):
    """Bytes that are not a little-endian CDR message of the expected type."""


class JointStateFields(NamedTuple):
    sec: int
    nanosec: int
    frame_id: str
    name: list[str]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]

    @property
    def stamp_ns(self) -> int:
        return stamps.join(self.sec, self.nanosec)

    @property
    def stamp_s(self) -> float:
        """As ``ros.conversions.stamp_to_s`` (sec + nanosec, not stamp_ns / 1e9: that rounds)."""
        return self.sec + self.nanosec * 1e-9


def header_stamp_ns(data: bytes) -> int:
    """header.stamp [ns] of any serialized stamped message (little-endian CDR; header first)."""
    if len(data) < 12 or data[:4] != LITTLE_ENDIAN_CDR:
        raise CdrError("not a little-endian CDR message with a header")
    sec, nanosec = _STAMP.unpack_from(data, 4)
    return stamps.join(sec, nanosec)


def write_header_stamp(buffer: bytearray, sec: int, nanosec: int) -> None:
    """Overwrite header.stamp in a serialized stamped message (a pre-built template)."""
    _STAMP.pack_into(buffer, 4, sec, nanosec)


class _Reader:
    """Reads in order; notes where the layout-defining bytes (counts, strings) and the double
    arrays were, for :class:`JointStateReader`."""

    __slots__ = ("arrays", "data", "end", "fixed", "pos")

    def __init__(self, data: bytes) -> None:
        if len(data) < 4 or data[:4] != LITTLE_ENDIAN_CDR:
            raise CdrError(
                f"encapsulation {data[:4].hex() or 'missing'}: not little-endian CDR (00010000)"
            )
        self.data, self.pos, self.end = data, 4, len(data)
        self.fixed: list[tuple[int, int]] = []  # (offset, length)
        self.arrays: list[tuple[int, int]] = []  # (offset, count) of each double array

    def _need(self, n: int, what: str) -> None:
        if self.pos + n > self.end:
            raise CdrError(
                f"{what}: needs {n} bytes at offset {self.pos}, the message has {self.end}"
            )

    def align(self, n: int) -> None:
        self.pos += -(self.pos - 4) % n

    def u32(self, what: str) -> int:
        self.align(4)
        self._need(4, what)
        (value,) = _U32.unpack_from(self.data, self.pos)
        self.fixed.append((self.pos, 4))
        self.pos += 4
        return int(value)

    def string(self, what: str) -> str:
        n = self.u32(what)
        if n == 0:
            raise CdrError(f"{what}: string length 0 at offset {self.pos - 4} (no terminating NUL)")
        self._need(n, what)
        raw = self.data[self.pos : self.pos + n]
        if raw[-1] != 0:
            raise CdrError(f"{what}: string at offset {self.pos} is not NUL-terminated")
        self.fixed.append((self.pos, n))
        self.pos += n
        try:
            return raw[:-1].decode()
        except UnicodeDecodeError as err:
            raise CdrError(f"{what}: not UTF-8 ({err})") from None

    def doubles(self, what: str) -> tuple[float, ...]:
        n = self.u32(what)
        if n == 0:
            return ()
        self.align(8)
        self._need(8 * n, what)  # before unpacking: a corrupt count must not allocate
        self.arrays.append((self.pos, n))
        values = struct.unpack_from(f"<{n}d", self.data, self.pos)
        self.pos += 8 * n
        return values

    def strings(self, what: str) -> list[str]:
        n = self.u32(what)
        self._need(5 * n, what)  # each string takes at least 5 bytes
        return [self.string(f"{what}[{i}]") for i in range(n)]


def _read_joint_state(data: bytes) -> tuple[JointStateFields, _Reader]:
    r = _Reader(data)
    r._need(8, "header.stamp")
    sec, nanosec = _STAMP.unpack_from(data, 4)
    r.pos = 12
    frame_id = r.string("header.frame_id")
    fields = JointStateFields(
        sec,
        nanosec,
        frame_id,
        r.strings("name"),
        r.doubles("position"),
        r.doubles("velocity"),
        r.doubles("effort"),
    )
    return fields, r


def decode_joint_state(data: bytes) -> JointStateFields:
    """``sensor_msgs/msg/JointState`` from its serialized bytes (:class:`CdrError` if not)."""
    return _read_joint_state(data)[0]


class JointStateReader:
    """:func:`decode_joint_state` for a stream: the layout of the last message is kept, and a
    message of the same size whose layout-defining bytes (frame_id, names, array lengths) are
    the same is read with one comparison per run of them and a single unpack. A driver's stream
    always is: about 2 us per message instead of 7 here. Anything else is decoded in full (and
    becomes the layout to compare with)."""

    def __init__(self) -> None:
        self._size = -1
        self._fixed: list[tuple[int, int, bytes]] = []
        self._unpack: struct.Struct | None = None
        self._template: JointStateFields | None = None
        self._counts: tuple[int, int, int] = (0, 0, 0)

    def __call__(self, data: bytes) -> JointStateFields:
        template = self._template
        if (
            template is not None
            and len(data) == self._size
            and data[:4] == LITTLE_ENDIAN_CDR
            and all(data[a:b] == ref for a, b, ref in self._fixed)
        ):
            values = self._unpack.unpack_from(data)  # type: ignore[union-attr]
            n_p, n_v, _ = self._counts
            return JointStateFields(
                values[0],
                values[1],
                template.frame_id,
                list(template.name),
                values[2 : 2 + n_p],
                values[2 + n_p : 2 + n_p + n_v],
                values[2 + n_p + n_v :],
            )
        fields, reader = _read_joint_state(data)
        self._learn(data, fields, reader)
        return fields

    def _learn(self, data: bytes, fields: JointStateFields, reader: _Reader) -> None:
        runs: list[list[int]] = []
        for offset, length in reader.fixed:  # merge adjacent ranges
            if runs and runs[-1][1] == offset:
                runs[-1][1] = offset + length
            else:
                runs.append([offset, offset + length])
        self._fixed = [(a, b, data[a:b]) for a, b in runs]
        fmt, pos = ["<4xiI"], 12
        for offset, count in reader.arrays:
            fmt.append(f"{offset - pos}x{count}d")
            pos = offset + 8 * count
        self._unpack = struct.Struct("".join(fmt))
        self._size = len(data)
        self._counts = (len(fields.position), len(fields.velocity), len(fields.effort))
        self._template = fields


class _Writer:
    __slots__ = ("parts", "pos")

    def __init__(self) -> None:
        self.parts: list[bytes] = [LITTLE_ENDIAN_CDR]
        self.pos = 4

    def align(self, n: int) -> None:
        pad = -(self.pos - 4) % n
        if pad:
            self.parts.append(b"\x00" * pad)
            self.pos += pad

    def raw(self, data: bytes) -> None:
        self.parts.append(data)
        self.pos += len(data)

    def u32(self, value: int) -> None:
        self.align(4)
        self.raw(_U32.pack(value))

    def string(self, text: str) -> None:
        data = text.encode() + b"\x00"
        self.u32(len(data))
        self.raw(data)

    def header(self, sec: int, nanosec: int, frame_id: str) -> None:
        self.raw(_STAMP.pack(sec, nanosec))
        self.string(frame_id)

    def doubles(self, values: tuple[float, ...] | list[float], fixed: bool = False) -> None:
        if not fixed:
            self.u32(len(values))
        if values:
            self.align(8)
            self.raw(struct.pack(f"<{len(values)}d", *values))

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def encode_joint_state(
    sec: int,
    nanosec: int,
    frame_id: str,
    name: list[str] | tuple[str, ...],
    *,
    position: list[float] | tuple[float, ...] = (),
    velocity: list[float] | tuple[float, ...] = (),
    effort: list[float] | tuple[float, ...] = (),
) -> bytes:
    """Serialized ``sensor_msgs/msg/JointState``, ready for ``Publisher.publish(bytes)``."""
    w = _Writer()
    w.header(sec, nanosec, frame_id)
    w.u32(len(name))
    for text in name:
        w.string(text)
    w.doubles(position)
    w.doubles(velocity)
    w.doubles(effort)
    return w.bytes()


def encode_wrench_stamped(
    sec: int,
    nanosec: int,
    frame_id: str,
    force: tuple[float, float, float],
    torque: tuple[float, float, float],
) -> bytes:
    """Serialized ``geometry_msgs/msg/WrenchStamped``."""
    w = _Writer()
    w.header(sec, nanosec, frame_id)
    w.doubles(force, fixed=True)
    w.doubles(torque, fixed=True)
    return w.bytes()
