"""Recover the readable part of a damaged bag into a new one, as ``mcap recover`` does for MCAP.

A recording cut short (power loss, a killed recorder, a copy that stopped) or damaged on disk
cannot be opened: rosbags, like rosbag2, needs the MCAP summary at the file's end, and sqlite
refuses a malformed database. What came before the damage is usually intact. This module reads
each storage file record by record and keeps what it can:

* **MCAP**: every schema, channel and message up to the point where the file ends or a record's
  framing is broken; a chunk that cannot be decompressed is skipped and reading goes on with the
  next record (the chunk's length is still known). Chunks carry no CRC in the files rosbag2 and
  rosbags write, so bytes changed inside a chunk that still decompresses are not detected here;
  a message that no longer deserializes is reported by the reader with its topic.
* **sqlite3**: the topics and message definitions, then the messages in blocks of ids; a block
  that sqlite cannot read is split until the unreadable ids are isolated.

Compressed bags are salvaged too: a compressed storage file (rosbag2's ``FILE`` mode,
``.db3.zstd``/``.mcap.zstd``) is decompressed as far as it goes into a temporary file and read
as above; with ``MESSAGE`` compression (metadata.yaml) each payload is decompressed, and one that
is not a whole zstd frame is left out and counted. The new bag is uncompressed.

Only what is proven readable is kept and reported: every message is deserialized with its type
before it is written, and the new bag is read back message by message before the salvage is
reported; a bag that does not read back is removed, never left half-written.

The salvaged messages are written with :class:`~transparency_ros.bag.writer.BagWriter` (MCAP,
atomically) with the original ``custom_data`` (from metadata.yaml, else from the copy rosbag2
keeps inside the storage), plus ``transparency.salvaged`` saying where from and what was lost.
Nothing is written when nothing could be salvaged.
"""

from __future__ import annotations

import shutil
import sqlite3
import tempfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
import zstandard
from mcap import records
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.typesys import Stores, get_typestore

from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.keys import SALVAGED_KEY
from transparency_ros.bag.reader import (
    STORAGE_SUFFIXES,
    normalise_type,
    open_bag,
    register_definition,
)
from transparency_ros.bag.writer import BagWriter

SQLITE_BLOCK = 1000  # message ids read at once
# what sqlite gives for damaged pages, and Python for damaged names in them (found by fuzzing)
SQLITE_ERRORS = (sqlite3.Error, UnicodeDecodeError)
SQLITE_EMPTY_BLOCKS = 20  # without max(id): blocks in a row with nothing readable end the search


@dataclass(frozen=True)
class Topic:
    name: str
    msgtype: str
    serialization_format: str
    definition: tuple[str, str] | None  # (encoding 'ros2msg' | 'ros2idl', text) when stored


@dataclass
class SalvageReport:
    source: Path
    out: Path | None  # None: nothing could be salvaged, nothing written
    kept: Counter[str] = field(default_factory=Counter)  # topic -> messages salvaged
    recorded: dict[str, int] = field(default_factory=dict)  # topic -> count in metadata.yaml
    damage: list[str] = field(default_factory=list)  # what was found, file by file

    @property
    def total(self) -> int:
        return sum(self.kept.values())


# ------------------------------------------------------------------------------- MCAP


def _mcap_items(path: Path, damage: list[str]) -> Iterator[tuple[str, Any]]:
    """('topic', Topic) and ('message', (topic, log ns, bytes)) in file order, and
    ('custom', dict) from rosbag2's metadata record; damage noted, never raised."""
    with path.open("rb") as stream:  # read as a stream: memory does not grow with the file
        yield from _mcap_stream(path, stream, damage)


def _mcap_stream(path: Path, stream: Any, damage: list[str]) -> Iterator[tuple[str, Any]]:
    schemas: dict[int, records.Schema] = {}
    channels: dict[int, str] = {}
    size = path.stat().st_size

    def handle(record: Any) -> Iterator[tuple[str, Any]]:
        if isinstance(record, records.Schema):
            schemas[record.id] = record
        elif isinstance(record, records.Channel):
            schema = schemas.get(record.schema_id)
            if schema is None:
                damage.append(f"{path.name}: channel {record.topic} has no schema; skipped")
                return
            definition = (schema.encoding, schema.data.decode("utf-8", "replace"))
            channels[record.id] = record.topic
            yield "topic", Topic(record.topic, normalise_type(schema.name),
                                 record.message_encoding, definition)  # fmt: skip
        elif isinstance(record, records.Message):
            topic = channels.get(record.channel_id)
            if topic is not None:
                yield "message", (topic, record.log_time, record.data)
        elif isinstance(record, records.Metadata) and record.name == "rosbag2":
            custom = _custom_from_yaml(record.metadata.get("serialized_metadata", ""))
            if custom:
                yield "custom", custom

    # the summary at the end (when it survived) repeats every schema and channel: with it, the
    # messages of later chunks survive a damaged first chunk, where rosbag2 writes them
    for record in _summary_records(stream):
        yield from handle(record)
    stream.seek(0)
    good = 0  # where the last complete record ends
    try:
        for record in StreamReader(stream, emit_chunks=True).records:
            good = stream.tell()
            if isinstance(record, records.Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as err:  # noqa: BLE001 - any decoding failure of one chunk
                    damage.append(
                        f"{path.name}: a chunk of {record.uncompressed_size} bytes "
                        f"({_span(record)}) cannot be read ({_reason(err)}); skipped"
                    )
                    continue
                for item in inner:
                    yield from handle(item)
            else:
                yield from handle(record)
    except Exception as err:  # noqa: BLE001 - the framing is broken: stop where it is
        end = "ends" if stream.tell() >= size else "is broken"
        damage.append(
            f"{path.name}: {end} after byte {good} of {size} ({_reason(err)}); "
            "the records after it are lost"
        )


def _summary_records(stream: Any) -> list[Any]:
    try:
        summary = make_reader(stream).get_summary()
    except Exception:  # noqa: BLE001 - no readable summary: the stream has to do
        return []
    if summary is None:
        return []
    return [*summary.schemas.values(), *summary.channels.values()]


def _span(chunk: records.Chunk) -> str:
    return f"log times {chunk.message_start_time}-{chunk.message_end_time} ns"


def _reason(err: BaseException) -> str:
    text = str(err).splitlines()[0] if str(err) else ""
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


# ------------------------------------------------------------------------------ sqlite3


def _sqlite_items(path: Path, damage: list[str]) -> Iterator[tuple[str, Any]]:
    with tempfile.TemporaryDirectory(prefix="salvage-") as tmp:
        readable = _padded(path, Path(tmp), damage)
        try:
            db = sqlite3.connect(f"file:{readable}?mode=ro", uri=True)
            db.text_factory = lambda raw: raw.decode("utf-8", "replace")  # damaged text too
        except SQLITE_ERRORS as err:
            damage.append(f"{path.name}: cannot open ({_reason(err)}); nothing salvaged")
            return
        try:
            yield from _sqlite_rows(db, path, damage)
        finally:
            db.close()


def _padded(path: Path, tmp: Path, damage: list[str]) -> Path:
    """A working copy in ``tmp`` (with the write-ahead log a crashed recorder may have left), so
    that reading never writes beside the user's bag (sqlite makes -shm/-wal files even to read a
    WAL database). sqlite refuses a file shorter than its header says (a truncated bag) even
    where the pages asked for are there: the copy is padded with zero pages, and reads up to the
    missing ones."""
    copy = tmp / path.name
    shutil.copyfile(path, copy)
    wal = path.with_name(path.name + "-wal")
    if wal.is_file():
        shutil.copyfile(wal, tmp / wal.name)
    with path.open("rb") as f:
        header = f.read(100)
    size = path.stat().st_size
    if len(header) < 100 or not header.startswith(b"SQLite format 3\x00"):
        return copy
    page = int.from_bytes(header[16:18], "big")
    page = 65536 if page == 1 else page
    declared = int.from_bytes(header[28:32], "big") * page
    if size >= declared:
        return copy
    damage.append(f"{path.name}: ends at byte {size} of {declared} (truncated)")
    with copy.open("ab") as f:
        f.truncate(declared)
    return copy


def _sqlite_rows(db: sqlite3.Connection, path: Path, damage: list[str]) -> Iterator[Any]:
    try:
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master")}
        topics = db.execute("SELECT id, name, type, serialization_format FROM topics").fetchall()
    except SQLITE_ERRORS as err:
        damage.append(
            f"{path.name}: the topics table is unreadable ({_reason(err)}); nothing salvaged"
        )
        return
    definitions = _sqlite_definitions(db, tables, path, damage)
    if "metadata" in tables:
        try:
            row = db.execute("SELECT metadata FROM metadata ORDER BY id DESC LIMIT 1").fetchone()
            custom = _custom_from_yaml(row[0]) if row else {}
        except SQLITE_ERRORS:
            custom = {}  # the copy in metadata.yaml, if any, is used
        if custom:
            yield "custom", custom
    names: dict[int, str] = {}
    for topic_id, name, msgtype, fmt in topics:
        if not all(isinstance(v, str) and v for v in (name, msgtype, fmt)):
            damage.append(f"{path.name}: topic row {topic_id} is damaged ({name!r}, {msgtype!r})")
            continue
        names[topic_id] = name
        normalised = normalise_type(msgtype)
        yield "topic", Topic(name, normalised, fmt, definitions.get(normalised))
    yield from _sqlite_messages(db, path, names, damage)


def _sqlite_messages(
    db: sqlite3.Connection, path: Path, names: dict[int, str], damage: list[str]
) -> Iterator[Any]:
    try:
        last: int | None = db.execute("SELECT max(id) FROM messages").fetchone()[0] or 0
    except SQLITE_ERRORS:
        last = None  # the highest ids are lost: read on until blocks stay empty
    lost: list[tuple[int, int]] = []
    start, empty, bad_rows = 1, 0, 0
    while (start <= last) if last is not None else (empty < SQLITE_EMPTY_BLOCKS):
        rows = _sqlite_block(db, start, start + SQLITE_BLOCK - 1, lost)
        empty = 0 if rows else empty + 1
        for topic_id, stamp, data in rows:
            if topic_id not in names:
                continue
            if not isinstance(stamp, int) or not isinstance(data, bytes) or stamp < 0:
                bad_rows += 1  # a damaged cell that sqlite still reads
                continue
            yield "message", (names[topic_id], stamp, data)
        start += SQLITE_BLOCK
    if bad_rows:
        damage.append(f"{path.name}: {bad_rows} message rows with damaged values; skipped")
    if lost:
        merged = _merge(lost)
        if last is None and merged[-1][1] == start - 1:  # probed past the end: open-ended
            merged[-1] = (merged[-1][0], -1)
        spans = ", ".join(
            f"{a} on" if b < 0 else f"{a}-{b}" if a != b else f"{a}" for a, b in merged[:10]
        )
        damage.append(f"{path.name}: message ids {spans} unreadable (malformed pages); skipped")


def _sqlite_definitions(
    db: sqlite3.Connection, tables: set[str], path: Path, damage: list[str]
) -> dict[str, tuple[str, str]]:
    """Type -> (encoding, definition) from the message_definitions table (rosbag2 Iron on)."""
    definitions: dict[str, tuple[str, str]] = {}
    if "message_definitions" in tables:
        try:
            for msgtype, encoding, text in db.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
            ):
                if all(isinstance(v, str) for v in (msgtype, encoding, text)):
                    definitions[normalise_type(msgtype)] = (encoding, text)
        except SQLITE_ERRORS as err:
            damage.append(f"{path.name}: message definitions unreadable ({_reason(err)})")
    return definitions


def _sqlite_block(
    db: sqlite3.Connection, lo: int, hi: int, lost: list[tuple[int, int]]
) -> list[tuple[int, int, bytes]]:
    try:
        return db.execute(
            "SELECT topic_id, timestamp, data FROM messages WHERE id BETWEEN ? AND ? ORDER BY id",
            (lo, hi),
        ).fetchall()
    except SQLITE_ERRORS:
        if lo == hi:
            lost.append((lo, hi))
            return []
        mid = (lo + hi) // 2
        return _sqlite_block(db, lo, mid, lost) + _sqlite_block(db, mid + 1, hi, lost)


def _merge(spans: list[tuple[int, int]]) -> list[tuple[int, int]]:
    merged: list[tuple[int, int]] = []
    for a, b in sorted(spans):
        if merged and a <= merged[-1][1] + 1:
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]))
        else:
            merged.append((a, b))
    return merged


# ------------------------------------------------------------------------------ metadata


def _custom_from_yaml(text: str) -> dict[str, str]:
    """custom_data of a rosbag2 metadata document ({} when it has none or is damaged)."""
    try:
        info = yaml.safe_load(text)
    except yaml.YAMLError:
        return {}
    return _custom_of(info)


def _bagfile_information(info: Any) -> dict[str, Any]:
    if isinstance(info, dict):
        inner = info.get("rosbag2_bagfile_information", info)
        if isinstance(inner, dict):
            return inner
    return {}


def _custom_of(info: Any) -> dict[str, str]:
    custom = _bagfile_information(info).get("custom_data")
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def _metadata(bag: Path, damage: list[str]) -> tuple[dict[str, str] | None, dict[str, int]]:
    """custom_data and the recorded message counts from metadata.yaml (None: no usable file)."""
    meta = bag / "metadata.yaml"
    if not meta.is_file():
        return None, {}
    try:
        document = yaml.safe_load(meta.read_text())
        info = _bagfile_information(document)
        if not info:
            raise ValueError("no rosbag2_bagfile_information")
        counts = {
            str(t["topic_metadata"]["name"]): int(t["message_count"])
            for t in info.get("topics_with_message_count") or []
        }
        if not isinstance(info.get("custom_data") or {}, dict):
            raise TypeError("custom_data is not a mapping")
    except (yaml.YAMLError, KeyError, TypeError, ValueError, UnicodeDecodeError) as err:
        damage.append(
            f"metadata.yaml: unreadable ({_reason(err)}); custom_data taken from the storage"
        )
        return None, {}
    return _custom_of(info), counts


# ------------------------------------------------------------------------------ salvage


COMPRESSED_SUFFIX = ".zstd"  # rosbag2's file compression: <storage file>.zstd


def _is_storage(path: Path) -> bool:
    name = path.name.removesuffix(COMPRESSED_SUFFIX)
    return Path(name).suffix in STORAGE_SUFFIXES


def storage_files(bag: Path) -> list[Path]:
    """A bag's storage files, compressed ones (``.db3.zstd``, ``.mcap.zstd``) included."""
    if bag.is_file():
        return [bag]
    return sorted(p for p in bag.iterdir() if _is_storage(p))


def _message_compression(bag: Path) -> str:
    """'zstd' when metadata.yaml says every message is compressed, else ''."""
    try:
        info = _bagfile_information(yaml.safe_load((bag / "metadata.yaml").read_text()))
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return ""
    mode = str(info.get("compression_mode") or "").upper()
    return str(info.get("compression_format") or "") if mode == "MESSAGE" else ""


def _decompressed(path: Path, tmp: Path, damage: list[str]) -> Path | None:
    """A ``.zstd`` storage file decompressed into ``tmp`` as far as it goes (None: nothing).
    A stream cut inside a frame keeps what its whole blocks gave; the damage says so."""
    out = tmp / path.name.removesuffix(COMPRESSED_SUFFIX)
    written, problem = 0, ""
    frame = zstandard.ZstdDecompressor().decompressobj()
    in_frame = False
    with path.open("rb") as src, out.open("wb") as dst:
        try:
            while chunk := src.read(1 << 20):
                while chunk:
                    block = frame.decompress(chunk)
                    dst.write(block)
                    written += len(block)
                    in_frame = not frame.eof
                    chunk = frame.unused_data if frame.eof else b""
                    if frame.eof:
                        frame = zstandard.ZstdDecompressor().decompressobj()
        except zstandard.ZstdError as err:
            problem = f"zstd stream damaged after {written} bytes ({_reason(err)})"
    if in_frame and not problem:
        problem = f"zstd stream cut inside a frame after {written} bytes"
    if problem:
        damage.append(f"{path.name}: {problem}" + ("; reading what came before" if written else ""))
    return out if written else None


class _Payloads:
    """Each message's payload as written: decompressed (MESSAGE compression) and proven to
    deserialize with its type; the ones that fail are counted per topic and left out."""

    def __init__(self, types: _Types, compression: str) -> None:
        self.types = types
        self.decompressor = zstandard.ZstdDecompressor() if compression == "zstd" else None
        self.msgtypes: dict[str, str] = {}
        self.bad: Counter[str] = Counter()
        self.why: dict[str, str] = {}

    def readable(self, topic: str, data: bytes) -> bytes | None:
        try:
            if self.decompressor is not None:
                data = self.decompressor.decompress(data)
            self.types.store.deserialize_cdr(data, self.msgtypes[topic])
        except Exception as err:  # noqa: BLE001 - any failure: this message is not readable
            self.bad[topic] += 1
            self.why.setdefault(topic, _reason(err))
            return None
        return data

    def report(self, damage: list[str]) -> None:
        for topic, count in sorted(self.bad.items()):
            damage.append(
                f"topic {topic}: {count} message(s) do not "
                f"{'decompress and ' if self.decompressor else ''}deserialize "
                f"({self.why[topic]}); left out"
            )


def _read_back(target: Path, kept: Counter[str]) -> None:
    """Read the new bag back, every message deserialized; raise if it differs from ``kept``."""
    counts: Counter[str] = Counter()
    with open_bag(target) as bag:
        for topic, _stamp, _msg in bag.messages(list(kept)):
            counts[topic] += 1
    if counts != kept:
        raise BagReadError(
            f"{target}: the salvaged bag does not read back as written "
            f"(read {dict(counts)}, wrote {dict(kept)}); removed"
        )


class _Types:
    """A Jazzy typestore to which the bag's own definitions are added, topic by topic."""

    def __init__(self, damage: list[str]) -> None:
        self.store = get_typestore(Stores.ROS2_JAZZY)
        self.damage = damage

    def known(self, topic: Topic) -> bool:
        if topic.msgtype in self.store.types:
            return True
        try:
            if topic.definition is None:
                raise KeyError("not defined in the bag")
            encoding, text = topic.definition
            register_definition(self.store, topic.msgtype, text, idl=encoding == "ros2idl")
        except Exception as err:  # noqa: BLE001 - any parser failure: that topic is left out
            self.damage.append(
                f"topic {topic.name}: type {topic.msgtype} unknown ({_reason(err)}); left out"
            )
            return False
        return True


def _declare(writer: BagWriter, topic: Topic, types: _Types, damage: list[str]) -> bool:
    try:
        writer.add(topic.name, topic.msgtype, typestore=types.store,
                   serialization_format=topic.serialization_format)  # fmt: skip
    except Exception as err:  # noqa: BLE001 - a damaged definition rosbags cannot write out
        damage.append(f"topic {topic.name}: type {topic.msgtype} not writable ({_reason(err)})")
        return False
    return True


class _NothingSalvagedError(Exception):
    pass


@dataclass
class _Copy:
    """What one salvage has declared and kept so far, file after file."""

    writer: BagWriter
    report: SalvageReport
    types: _Types
    payloads: _Payloads
    seen: set[str] = field(default_factory=set)
    written: set[str] = field(default_factory=set)  # topics declared in the new bag
    stored_custom: dict[str, str] = field(default_factory=dict)

    def file(self, path: Path) -> None:
        items = _mcap_items if path.suffix == ".mcap" else _sqlite_items
        for kind, value in items(path, self.report.damage):
            if kind == "message":
                self._message(*value)
            elif kind == "topic" and value.name not in self.seen:
                self.seen.add(value.name)
                if self.types.known(value) and _declare(
                    self.writer, value, self.types, self.report.damage
                ):
                    self.written.add(value.name)
                    self.payloads.msgtypes[value.name] = normalise_type(value.msgtype)
            elif kind == "custom":
                self.stored_custom.update(value)

    def _message(self, topic: str, stamp_ns: int, raw: bytes) -> None:
        if topic in self.written and (data := self.payloads.readable(topic, raw)) is not None:
            self.writer.write(topic, stamp_ns, data)
            self.report.kept[topic] += 1


def salvage(
    bag: str | Path,
    out: str | Path | None = None,
    progress: Callable[[str], None] = lambda _text: None,
) -> SalvageReport:
    """Copy what is readable of ``bag`` (a bag directory or one storage file) into ``out``
    (default ``<bag>.salvaged``), message by message (memory does not grow with the bag)."""
    source = Path(bag)
    if not source.exists():
        raise BagReadError(f"{source}: no such bag")
    files = storage_files(source)
    if not files:
        raise BagReadError(f"{source}: no .mcap or .db3 files (or their .zstd) to salvage")
    target = Path(out) if out is not None else source.with_name(source.name + ".salvaged")
    report = SalvageReport(source, None)
    folder = source if source.is_dir() else source.parent
    custom, report.recorded = _metadata(folder, report.damage)
    types = _Types(report.damage)
    payloads = _Payloads(types, _message_compression(folder))
    try:
        with tempfile.TemporaryDirectory() as tmp, BagWriter(target) as writer:
            copy = _Copy(writer, report, types, payloads)
            for path in files:
                progress(f"reading {path.name}")
                if path.suffix != COMPRESSED_SUFFIX:
                    copy.file(path)
                elif (plain := _decompressed(path, Path(tmp), report.damage)) is None:
                    report.damage.append(f"{path.name}: nothing decompresses; left out")
                else:
                    copy.file(plain)
                    plain.unlink()
            payloads.report(report.damage)
            if not report.kept:
                raise _NothingSalvagedError
            data = dict(copy.stored_custom if custom is None else custom)
            lost = "; ".join(report.damage) or "no damage found"
            data[SALVAGED_KEY] = f"from {source}: {lost}"
            for key, value in data.items():
                writer.set_custom(key, value)
    except _NothingSalvagedError:
        report.damage.append("no message could be read: nothing written")
        return report
    try:
        _read_back(target, report.kept)
    except Exception:
        shutil.rmtree(target, ignore_errors=True)
        raise
    report.out = target
    return report
