"""Read any rosbag2 bag into Python values and numpy arrays (rosbags underneath, no rclpy).

What it opens: a bag directory (metadata.yaml, versions 4-9) in MCAP or sqlite3 storage, with
file or message compression and split files; a directory of .mcap files without metadata.yaml
(each file read in name order); a single .mcap or .db3 file.

Known traps it handles:
* **QoS mismatch.** rosbags pairs a bag's metadata connections with the storage's by equality,
  QoS profiles included; when the metadata's QoS differs from the storage's (bags converted by
  other tools), it yields *zero* messages without an error. Every topic read is checked against
  the recorded message count; a topic that came back empty is read again from the storage files
  directly, which yields its messages (``recovered_topics`` says which).
* **Types.** Types missing from the ROS 2 Jazzy typestore are registered from the definitions the
  bag embeds (MCAP schemas, sqlite3 message_definitions); legacy names without ``/msg/``
  (``test_msgs/BasicTypes``) are normalised. A type the bag does not define is a clear error.

Arrays (:func:`joint_series`, :func:`scalar_series`) come from the fast path of
:mod:`transparency_ros.bag.fast` where a stream has a fixed layout in MCAP storage (about 25x
rosbags' speed; every field identical), else from deserializing message by message.

Every error is a :class:`BagReadError` naming the bag and, where it applies, the topic.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.fast import FieldArrays, read_fields
from transparency_ros.core import stamps

STORAGE_SUFFIXES = (".mcap", ".db3")


def _first_line(err: BaseException) -> str:
    return str(err).splitlines()[0].rstrip(".") if str(err) else type(err).__name__


JOINT_STATE = "sensor_msgs/msg/JointState"


def normalise_type(name: str) -> str:
    """'pkg/Name' (legacy) -> 'pkg/msg/Name'; other names unchanged."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


def register_definition(typestore: Any, msgtype: str, text: str, *, idl: bool) -> dict[str, Any]:
    """Add the types of a definition a bag embeds (.msg text, or IDL) to ``typestore``; the
    types added. Raises whatever the parser raises on a definition it cannot read."""
    types = get_types_from_idl(text) if idl else get_types_from_msg(text, msgtype)
    typestore.register(types)
    return dict(types)


@dataclass(frozen=True)
class TopicInfo:
    msgtype: str
    count: int  # as recorded (metadata / storage summary)
    serialization_format: str


@dataclass
class BagSource:
    """An open bag. Use as a context manager; see :func:`open_bag`."""

    path: Path
    storage_paths: list[Path]
    _readers: list[Reader] = field(default_factory=list)
    typestore: Any = field(default_factory=lambda: get_typestore(Stores.ROS2_JAZZY))
    recovered_topics: set[str] = field(default_factory=set)
    type_errors: dict[str, str] = field(default_factory=dict)  # topic -> why it cannot be read

    # ----------------------------------------------------------------- open / close

    def __enter__(self) -> BagSource:
        try:
            if (self.path / "metadata.yaml").exists() or self.path.is_file():
                self._readers = [Reader(self.path)]
            else:
                self._readers = [Reader(p) for p in self.storage_paths]
            for reader in self._readers:
                reader.open()
        except Exception as err:
            # ReaderError: sqlite/apsw, zstd, struct, Memory- and OverflowError (fuzzing found)
            self.close()
            raise BagReadError(self._damaged("cannot open", err)) from err
        self._register_types()
        return self

    def _damaged(self, doing: str, err: BaseException) -> str:
        """The error message: which storage file fails on its own, and how to recover it."""
        what = f"{self.path}: {doing}: {_first_line(err)}"
        for path in self.storage_paths:
            try:
                with Reader(path):
                    pass
            except Exception as file_err:  # noqa: BLE001 - as in __enter__
                if path != self.path:
                    what = f"{self.path}: {doing}: file {path.name}: {_first_line(file_err)}"
                break
        if "serialization format" in what.lower():  # not damage: nothing to salvage
            return f"{what}. Only cdr bags can be read (the format the recorder's middleware wrote)"
        return f"{what}. `transparency salvage {self.path}` copies what is readable"

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        for reader in self._readers:
            if reader.is_open:
                reader.close()
        self._readers = []

    # ----------------------------------------------------------------- what is in it

    @property
    def connections(self) -> list[Connection]:
        return [c for reader in self._readers for c in reader.connections]

    @property
    def topics(self) -> dict[str, TopicInfo]:
        topics: dict[str, TopicInfo] = {}
        for c in self.connections:
            fmt = getattr(c.ext, "serialization_format", "cdr")
            known = topics.get(c.topic)
            count = c.msgcount + (known.count if known else 0)
            topics[c.topic] = TopicInfo(normalise_type(c.msgtype), count, fmt)
        return topics

    @property
    def custom_data(self) -> dict[str, str]:
        data: dict[str, str] = {}
        for reader in self._readers:
            custom = getattr(reader.storage.metadata, "custom", None)
            data.update(custom or {})
        return data

    def require_custom(self, *keys: str) -> dict[str, str]:
        data = self.custom_data
        missing = [k for k in keys if k not in data]
        if missing:
            raise BagReadError(f"{self.path}: metadata custom_data lacks {', '.join(missing)}")
        return {k: data[k] for k in keys}

    def require_topic(self, topic: str, msgtype: str | None = None) -> TopicInfo:
        info = self.topics.get(topic)
        if info is None:
            have = ", ".join(sorted(self.topics)) or "none"
            raise BagReadError(f"{self.path}: no topic {topic} (topics: {have})")
        if msgtype is not None and info.msgtype != msgtype:
            raise BagReadError(f"{self.path}: topic {topic} is {info.msgtype}, expected {msgtype}")
        return info

    # ----------------------------------------------------------------- messages

    def _register_types(self) -> None:
        known = set(self.typestore.types)
        for c in self.connections:
            name = normalise_type(c.msgtype)
            if name in known or c.msgdef is None or not c.msgdef.data.strip():
                continue
            try:
                idl = c.msgdef.format == MessageDefinitionFormat.IDL
                types = register_definition(self.typestore, name, c.msgdef.data, idl=idl)
                known |= set(types)
            except Exception as err:  # noqa: BLE001 - any parser failure: name the topic
                # other topics stay readable; reading this one raises (see messages())
                self.type_errors[c.topic] = (
                    f"{self.path}: topic {c.topic}: cannot parse the embedded definition of "
                    f"{c.msgtype}: {str(err).splitlines()[0]}"
                )

    def raw(self, topics: Sequence[str]) -> Iterator[tuple[Connection, int, bytes]]:
        """(connection, log time [ns], CDR bytes) of the given topics, in storage order per
        file; empty topics whose recorded count says otherwise are recovered (QoS mismatch)."""
        for topic in topics:
            self.require_topic(topic)
        for topic in topics:
            info = self.topics[topic]
            if info.serialization_format != "cdr":
                raise BagReadError(
                    f"{self.path}: topic {topic}: serialization format "
                    f"{info.serialization_format!r} is not cdr"
                )
        yielded = dict.fromkeys(topics, 0)
        try:
            for reader in self._readers:
                wanted = [c for c in reader.connections if c.topic in yielded]
                if wanted:
                    for conn, stamp, data in reader.messages(connections=wanted):
                        yielded[conn.topic] += 1
                        yield conn, stamp, data
        except Exception as err:
            # sqlite/apsw, zstd/lz4 and struct errors as well as its own ReaderError
            raise BagReadError(self._damaged(f"reading {', '.join(topics)}", err)) from err
        empty = [t for t in topics if yielded[t] == 0 and self.topics[t].count > 0]
        if empty:
            yield from self._recover(empty)

    def _recover(self, topics: list[str]) -> Iterator[tuple[Connection, int, bytes]]:
        """Read topics straight from the storage files (metadata QoS did not match)."""
        got = 0
        for path in self.storage_paths:
            try:
                with Reader(path) as reader:
                    wanted = [c for c in reader.connections if c.topic in topics]
                    for item in reader.messages(connections=wanted):
                        got += 1
                        yield item
            except Exception as err:
                raise BagReadError(f"{self.path}: recovering {', '.join(topics)}: {err}") from err
        if got == 0:
            raise BagReadError(
                f"{self.path}: topics {', '.join(topics)} record messages in the metadata but "
                "none could be read from the storage"
            )
        self.recovered_topics.update(topics)

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time [ns], deserialized message)."""
        for topic in topics:
            if topic in self.type_errors:
                raise BagReadError(self.type_errors[topic])
        for conn, stamp, data in self.raw(topics):
            msgtype = normalise_type(conn.msgtype)
            try:
                msg = self.typestore.deserialize_cdr(data, msgtype)
            except KeyError:
                raise BagReadError(
                    f"{self.path}: topic {conn.topic}: unknown message type {conn.msgtype} "
                    "(not in ROS 2 Jazzy and not defined in the bag)"
                ) from None
            except Exception as err:
                raise BagReadError(
                    f"{self.path}: topic {conn.topic}: cannot deserialize a {msgtype} at "
                    f"{stamp} ns: {err}"
                ) from err
            yield conn.topic, stamp, msg


def open_bag(path: str | Path) -> BagSource:
    """A :class:`BagSource` for a bag directory, a directory of .mcap files or a storage file."""
    p = Path(path)
    if not p.exists():
        raise BagReadError(f"{p}: no such bag")
    if p.is_file():
        if p.suffix not in STORAGE_SUFFIXES:
            raise BagReadError(f"{p}: not a bag (expected a directory, .mcap or .db3)")
        return BagSource(p, [p])
    files = sorted(f for f in p.iterdir() if f.suffix in STORAGE_SUFFIXES)
    if not (p / "metadata.yaml").exists() and not files:
        raise BagReadError(f"{p}: neither metadata.yaml nor .mcap/.db3 files")
    return BagSource(p, files)


def find_bags(paths: Sequence[str | Path]) -> list[Path]:
    """Bag directories under the given paths (a bag itself, or directories holding bags)."""
    found: list[Path] = []
    for raw in paths:
        p = Path(raw)
        if not p.exists():
            raise BagReadError(f"{p}: no such bag or directory")
        if (p / "metadata.yaml").exists() or p.is_file():
            found.append(p)
            continue
        found += sorted(m.parent for m in p.rglob("metadata.yaml"))
    if not found:
        raise BagReadError(
            f"no bags (directories with metadata.yaml) under {', '.join(map(str, paths))}"
        )
    return found


# --------------------------------------------------------------------- arrays


def stamp_ns(header: Any) -> int:
    """A header's stamp as integer nanoseconds (exact)."""
    return stamps.join(header.stamp.sec, header.stamp.nanosec)


class _Stamped:
    stamp_ns: np.ndarray

    @property
    def stamp_s(self) -> np.ndarray:
        """Stamps as float seconds: for fitting and plots, not for matching stamps (at today's
        epoch a float64 second resolves about 240 ns)."""
        return self.seconds(0)

    def seconds(self, origin_ns: int) -> np.ndarray:
        """Seconds since ``origin_ns`` (exact differences first, then float)."""
        return np.asarray((self.stamp_ns - np.int64(origin_ns)) * 1e-9, dtype=float)


@dataclass(frozen=True)
class JointSeries(_Stamped):
    stamp_ns: np.ndarray  # (n,) int64: header stamps, exact
    position: np.ndarray  # (n,)
    velocity: np.ndarray  # (n,), NaN where absent
    effort: np.ndarray  # (n,), NaN where absent


@dataclass(frozen=True)
class ScalarSeries(_Stamped):
    stamp_ns: np.ndarray  # (n,) int64: header stamps, exact
    value: np.ndarray  # (n,)

    def __len__(self) -> int:
        return int(self.stamp_ns.size)


def _fields(bag: BagSource, topic: str) -> FieldArrays | None:
    """The fast path (:mod:`transparency_ros.bag.fast`) where it applies."""
    if topic in bag.type_errors:
        return None
    return read_fields(bag.storage_paths, topic, bag.typestore, normalise_type)


def _stamps(fields: FieldArrays) -> np.ndarray:
    sec, nanosec = fields.fields["header.stamp.sec"], fields.fields["header.stamp.nanosec"]
    return sec.astype(np.int64) * stamps.NS_PER_S + nanosec.astype(np.int64)  # as stamp_ns()


def _fast_joint_series(bag: BagSource, topic: str, joint: str | None) -> JointSeries | None:
    fields = _fields(bag, topic)
    if fields is None:
        return None
    names = list(bag.typestore.deserialize_cdr(fields.first_message, JOINT_STATE).name)
    if joint is not None and joint not in names:
        empty = np.empty(0)
        return JointSeries(np.empty(0, dtype=np.int64), empty, empty, empty)
    index = names.index(joint) if joint is not None else 0
    stamp = _stamps(fields)
    order = np.argsort(stamp, kind="stable")
    nan = np.full(stamp.size, np.nan)

    def at(name: str) -> np.ndarray:
        return fields.fields.get(f"{name}[{index}]", nan).astype(float)[order]

    return JointSeries(stamp[order], at("position"), at("velocity"), at("effort"))


def joint_series(bag: BagSource, topic: str, joint: str | None = None) -> JointSeries:
    """One joint of a JointState topic as arrays (the first joint when ``joint`` is None)."""
    bag.require_topic(topic, JOINT_STATE)
    fast = _fast_joint_series(bag, topic, joint)
    if fast is not None:
        return fast
    stamps: list[int] = []
    rows: list[tuple[float, float, float]] = []
    for _topic, _log, msg in bag.messages([topic]):
        names = list(msg.name)
        index = names.index(joint) if joint is not None and joint in names else 0
        if joint is not None and joint not in names:
            continue

        def at(values: Any, i: int = index) -> float:
            return float(values[i]) if len(values) > i else float("nan")

        stamps.append(stamp_ns(msg.header))
        rows.append((at(msg.position), at(msg.velocity), at(msg.effort)))
    stamp = np.array(stamps, dtype=np.int64)
    order = np.argsort(stamp, kind="stable")
    data = np.array(rows, dtype=float).reshape(-1, 3)[order]
    return JointSeries(stamp[order], data[:, 0], data[:, 1], data[:, 2])


def scalar_series(bag: BagSource, topic: str, msgtype: str, field_path: str) -> ScalarSeries:
    """One field of a stamped message over time, in stamp order; ``field_path`` like
    'wrench.force.z' or 'point.z'."""
    bag.require_topic(topic, msgtype)
    fields = _fields(bag, topic)
    if fields is not None and field_path in fields.fields:
        stamp, value = _stamps(fields), fields.fields[field_path].astype(float)
    else:
        parts = field_path.split(".")
        stamps, values = [], []
        for _topic, _log, msg in bag.messages([topic]):
            item: Any = msg
            for part in parts:
                item = getattr(item, part)
            stamps.append(stamp_ns(msg.header))
            values.append(float(item))
        stamp, value = np.array(stamps, dtype=np.int64), np.array(values, dtype=float)
    order = np.argsort(stamp, kind="stable")
    return ScalarSeries(stamp[order], value[order])
