"""Numeric fields of fixed-layout messages straight from MCAP chunks into numpy arrays.

Deserializing message by message (rosbags, mcap-ros2-support) costs 15-30 us a message. Sensor
streams do not need it: every message of a JointState stream with the same joint names, or of a
WrenchStamped stream with the same frame_id, has the same CDR layout, so each numeric field sits
at the same byte offset of every message. This module

1. walks the MCAP file's chunks (decompressed with zstd or lz4) and indexes their message
   records with a compiled loop (:func:`_index_records`): channel, log time, where the data is;
2. works out the layout of a topic's first message from the type definition (CDR rules:
   little-endian, alignment relative to the payload after the 4-byte encapsulation header);
3. checks that every message of the topic has the same length and the same bytes wherever the
   layout depends on them (string lengths and contents, sequence counts);
4. gathers each numeric field of all messages with one fancy-indexing operation per chunk.

When any check fails (a stream whose layout changes, big-endian CDR, a file without a summary,
another storage format) it returns None and the caller falls back to rosbags. Values are the
bytes of the message reinterpreted, so they are identical to what a deserializer gives (a test
compares every field of every message against rosbags).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from transparency_ros.core.compiled import jit_on_first_call

_SIZES = {
    "bool": 1,
    "byte": 1,
    "char": 1,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "float32": 4,
    "int64": 8,
    "uint64": 8,
    "float64": 8,
}
_DTYPES = {
    "bool": "<u1",
    "byte": "<u1",
    "char": "<u1",
    "int8": "<i1",
    "uint8": "<u1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "float32": "<f4",
    "int64": "<i8",
    "uint64": "<u8",
    "float64": "<f8",
}
BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4  # rosbags' Nodetype values
MESSAGE_OPCODE = 0x05
CHUNK_OPCODE = 0x06
MAGIC = b"\x89MCAP0\r\n"
# more numeric fields than this (an image, a point cloud): not a stream of samples, no fast path
MAX_LEAVES = 256


@dataclass(frozen=True)
class Leaf:
    """A numeric field of a message: its path (``position[0]``), type and byte offset."""

    path: str
    dtype: str
    offset: int


@dataclass(frozen=True)
class Layout:
    size: int  # bytes of every message
    leaves: list[Leaf]
    fixed: list[tuple[int, int]]  # byte ranges every message must share (strings, counts)


class _Walker:
    def __init__(self, typestore: Any, data: bytes) -> None:
        self.typestore, self.data = typestore, data
        self.pos = 4  # after the encapsulation header
        self.leaves: list[Leaf] = []
        self.fixed: list[tuple[int, int]] = []

    def align(self, n: int) -> None:
        self.pos = 4 + -(-(self.pos - 4) // n) * n

    def count(self) -> int:
        self.align(4)
        (n,) = struct.unpack_from("<I", self.data, self.pos)
        self.fixed.append((self.pos, 4))
        self.pos += 4
        return int(n)

    def node(self, path: str, node: tuple[int, Any]) -> None:
        kind, detail = node
        if kind == BASE:
            name = detail[0]
            if name == "wstring":
                raise ValueError("wstring: not read here")  # (its width is not one byte)
            if name == "string":
                n = self.count()
                self.fixed[-1] = (self.fixed[-1][0], 4 + n)  # the length and the text
                self.pos += n
                return
            size = _SIZES[name]
            self.align(size)
            if len(self.leaves) == MAX_LEAVES:
                raise ValueError("too many fields")
            self.leaves.append(Leaf(path, _DTYPES[name], self.pos))
            self.pos += size
        elif kind == NAME:
            for field, sub in self.typestore.fielddefs[detail][1]:
                self.node(f"{path}.{field}" if path else field, sub)
        elif kind == ARRAY:
            for i in range(detail[1]):
                self.node(f"{path}[{i}]", detail[0])
        elif kind == SEQUENCE:
            for i in range(self.count()):
                self.node(f"{path}[{i}]", detail[0])
        else:
            raise ValueError(f"unknown node type {kind}")


def layout(typestore: Any, msgtype: str, data: bytes) -> Layout | None:
    """The layout of one CDR message (None: big-endian, or the walk overruns the data)."""
    if len(data) < 4 or data[1] != 1:  # 0x0001: CDR little-endian
        return None
    walker = _Walker(typestore, data)
    try:
        walker.node("", (NAME, msgtype))
    except (struct.error, KeyError, ValueError):
        return None
    if not len(data) - 8 < walker.pos <= len(data):  # all of it read, but for padding
        return None
    return Layout(len(data), walker.leaves, walker.fixed)


@jit_on_first_call
def _index_records(buf: Any, out: Any) -> int:
    """(channel, log time, data start, data length) of every message record in ``buf`` (the
    records of a chunk), into ``out`` (rows); how many were found (-1: malformed)."""
    i, n, size = 0, 0, buf.shape[0]
    while i + 9 <= size:
        opcode = buf[i]
        length = np.int64(0)
        for k in range(8):
            length |= np.int64(buf[i + 1 + k]) << (8 * k)
        start = i + 9
        if length < 0 or start + length > size:
            return -1
        if opcode == MESSAGE_OPCODE and length >= 22:
            channel = np.int64(buf[start]) | (np.int64(buf[start + 1]) << 8)
            log_time = np.int64(0)
            for k in range(8):
                log_time |= np.int64(buf[start + 6 + k]) << (8 * k)
            out[n, 0] = channel
            out[n, 1] = log_time
            out[n, 2] = start + 22
            out[n, 3] = length - 22
            n += 1
        i = int(start + length)
    return n


def _chunks(path: Path) -> Any:
    """Decompressed record buffers of every chunk of an MCAP file. The top-level records are
    walked here (opcode, length): only chunks are parsed, the message indexes after each are
    skipped (parsing them record by record cost more than reading the messages)."""
    import mmap  # noqa: PLC0415

    with path.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        if data[:8] != MAGIC:
            raise ValueError(f"{path}: not an MCAP file")
        pos, end = 8, len(data) - 8
        while pos + 9 <= end:
            opcode = data[pos]
            (length,) = struct.unpack_from("<Q", data, pos + 1)
            body = pos + 9
            pos = body + length
            if opcode == MESSAGE_OPCODE:  # outside a chunk: not read here, so no fast path
                raise ValueError(f"{path}: messages outside chunks")
            if opcode != CHUNK_OPCODE:
                continue
            if pos > end + 8:
                raise ValueError(f"{path}: truncated chunk")
            (_start, _end, size, _crc, n) = struct.unpack_from("<QQQII", data, body)
            compression = bytes(data[body + 32 : body + 32 + n]).decode()
            (stored,) = struct.unpack_from("<Q", data, body + 32 + n)
            first = body + 40 + n
            try:
                raw = _decompress(data[first : first + stored], compression, size)
            except ValueError:
                raise
            except Exception as err:
                raise ValueError(f"{path}: chunk at byte {body - 9}: {err}") from err
            yield np.frombuffer(raw, np.uint8)


def _decompress(raw: bytes, compression: str, size: int) -> bytes:
    if compression == "zstd":
        import zstandard  # noqa: PLC0415

        return bytes(zstandard.ZstdDecompressor().decompress(raw, max_output_size=size))
    if compression == "lz4":
        import lz4.frame  # noqa: PLC0415

        return bytes(lz4.frame.decompress(raw))
    if compression == "":
        return bytes(raw)
    raise ValueError(f"unknown chunk compression {compression!r}")


def _channels(path: Path) -> dict[str, tuple[int, str, int | None]] | None:
    """topic -> (channel id, schema name, message count if the summary has statistics) from
    the file's summary (None: no summary)."""
    from mcap.reader import make_reader  # noqa: PLC0415

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None:
        return None
    counts = summary.statistics.channel_message_counts if summary.statistics else None
    out = {}
    for cid, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        if schema is not None and channel.message_encoding == "cdr":
            count = None if counts is None else counts.get(cid, 0)
            out[channel.topic] = (cid, schema.name, count)
    return out


@dataclass
class FieldArrays:
    """The numeric fields of every message of a topic, in storage order."""

    log_time_ns: npt.NDArray[np.int64]
    fields: dict[str, np.ndarray]
    layout: Layout
    first_message: bytes  # (the layout's strings, e.g. joint names, read from it)


class _Gather:
    """The fields of one topic, chunk by chunk; False from :meth:`add`: no fast path."""

    def __init__(self, typestore: Any, normalise: Any) -> None:
        self.typestore, self.normalise = typestore, normalise
        self.layout: Layout | None = None
        self.first = b""
        self.times: list[np.ndarray] = []
        self.parts: dict[str, list[np.ndarray]] = {}
        self.count = 0

    def add(self, buf: np.ndarray, rows: np.ndarray, schema: str) -> bool:
        if self.layout is None:
            self.first = bytes(buf[rows[0, 2] : rows[0, 2] + rows[0, 3]])
            self.layout = layout(self.typestore, self.normalise(schema), self.first)
            if self.layout is None:
                return False
            self.parts = {leaf.path: [] for leaf in self.layout.leaves}
        lay = self.layout
        if not np.all(rows[:, 3] == lay.size):
            return False
        starts = rows[:, 2]
        ref = np.frombuffer(self.first, dtype=np.uint8)
        for off, length in lay.fixed:
            cols = buf[starts[:, None] + (off + np.arange(length))]
            if not np.array_equal(cols, np.broadcast_to(ref[off : off + length], cols.shape)):
                return False
        for leaf in lay.leaves:
            width = np.dtype(leaf.dtype).itemsize
            cols = buf[starts[:, None] + (leaf.offset + np.arange(width))]
            self.parts[leaf.path].append(np.ascontiguousarray(cols).view(leaf.dtype)[:, 0])
        self.times.append(rows[:, 1])
        self.count += rows.shape[0]
        return True

    def result(self) -> FieldArrays | None:
        if self.layout is None:
            return None
        return FieldArrays(
            np.concatenate(self.times),
            {k: np.concatenate(v) for k, v in self.parts.items()},
            self.layout,
            self.first,
        )


def read_topics(
    paths: list[Path], topics: list[str], typestore: Any, normalise: Any = lambda n: n
) -> dict[str, FieldArrays | None]:
    """Every numeric field of each of ``topics`` from MCAP files ``paths`` (in order), in one
    pass over the chunks; None for a topic where the fast path does not apply and the caller
    must deserialize (see the module docstring)."""
    none: dict[str, FieldArrays | None] = dict.fromkeys(topics)
    if not paths or any(p.suffix != ".mcap" for p in paths):
        return none
    gathers = {t: _Gather(typestore, normalise) for t in topics}
    failed: set[str] = set()
    try:
        for path in paths:
            channels = _channels(path)
            if channels is None:
                return none
            wanted = {channels[t][0]: (t, channels[t][1]) for t in topics if t in channels}
            before = {t: g.count for t, g in gathers.items()}
            for buf in _chunks(path):
                index = np.empty((buf.size // 31 + 1, 4), dtype=np.int64)  # >= 31 B a record
                n = _index_records(buf, index)
                if n < 0:
                    return none
                for cid, (topic, schema) in wanted.items():
                    rows = index[:n][index[:n, 0] == cid]
                    if (
                        rows.size
                        and topic not in failed
                        and not gathers[topic].add(buf, rows, schema)
                    ):
                        failed.add(topic)
            # every message the file's statistics count was read, or no fast path
            for topic in topics:
                expected = channels[topic][2] if topic in channels else 0
                if expected is not None and gathers[topic].count - before[topic] != expected:
                    failed.add(topic)
    except (OSError, ValueError, KeyError, ImportError, EOFError, struct.error):
        return none
    return {t: None if t in failed else g.result() for t, g in gathers.items()}


def read_fields(
    paths: list[Path], topic: str, typestore: Any, normalise: Any = lambda n: n
) -> FieldArrays | None:
    """:func:`read_topics` for one topic."""
    return read_topics(paths, [topic], typestore, normalise)[topic]
