"""Write rosbag2 bags in MCAP storage (profile ``ros2``, message definitions embedded), atomically.

A bag is written into ``<name>.partial`` next to its final path and renamed when it is closed, so
a reader never sees a half-written bag; a failure removes the partial directory. Ctrl-C or
SIGTERM (see :mod:`transparency_ros.core.interrupts`) closes the bag with everything written so
far and ``custom_data`` ``transparency.interrupted`` naming the signal. Before anything
is recorded, :func:`check_writable` tells whether the directory can take a bag (exists or can be
made, is writable, has free space), so a trial is not run for nothing.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.rosbag2 import (
    CompressionFormat,
    CompressionMode,
    StoragePlugin,
    Writer,
    WriterError,
)
from rosbags.typesys import Stores, get_typestore

from transparency_ros.bag.errors import BagWriteError
from transparency_ros.bag.keys import INTERRUPTED_KEY
from transparency_ros.core.interrupts import deferred_interrupts, interruption_name

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MIN_FREE_BYTES = 50 * 1024 * 1024


def check_writable(directory: Path, min_free_bytes: int = MIN_FREE_BYTES) -> None:
    """Raise :class:`BagWriteError` if bags cannot be written into ``directory``."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BagWriteError(f"cannot create bag directory {directory}: {err.strerror}") from err
    if not os.access(directory, os.W_OK | os.X_OK):
        raise BagWriteError(f"bag directory {directory} is not writable")
    free = shutil.disk_usage(directory).free
    if free < min_free_bytes:
        raise BagWriteError(
            f"only {free / 1e6:.1f} MB free in {directory}; need {min_free_bytes / 1e6:.0f} MB"
        )


class BagWriter:
    """``with BagWriter(path, custom_data) as bag: bag.add(topic, type); bag.write(...)``."""

    def __init__(self, path: Path, custom_data: Mapping[str, str] | None = None) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise BagWriteError(f"bag {self.path} exists already; refusing to overwrite it")
        self.partial = self.path.with_name(self.path.name + ".partial")
        if self.partial.exists():
            shutil.rmtree(self.partial)  # left by an earlier crash: never a valid bag
        self._writer = Writer(self.partial, version=9, storage_plugin=StoragePlugin.MCAP)
        # zstd-compressed MCAP chunks, as `ros2 bag record --storage-preset-profile zstd_fast`
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._custom = dict(custom_data or {})
        self._connections: dict[str, Any] = {}
        self.count = 0

    def __enter__(self) -> BagWriter:
        try:
            self._writer.open()
        except (WriterError, OSError) as err:
            raise BagWriteError(f"cannot open bag {self.partial}: {err}") from err
        for key, value in self._custom.items():
            self._writer.set_custom_data(key, value)
        return self

    def add(
        self,
        topic: str,
        msgtype: str,
        *,
        typestore: Any = None,
        serialization_format: str = "cdr",
    ) -> None:
        """Declare a topic (once); ``typestore`` defines its type (default: ROS 2 Jazzy's)."""
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(
                topic,
                msgtype,
                typestore=typestore or TYPESTORE,
                serialization_format=serialization_format,
            )

    def set_custom(self, key: str, value: str) -> None:
        """A custom_data entry (written when the bag is closed)."""
        self._writer.set_custom_data(key, value)

    def write(self, topic: str, log_time_ns: int, cdr: bytes) -> None:
        connection = self._connections.get(topic)
        if connection is None:
            raise BagWriteError(f"bag {self.path}: topic {topic} was not added before writing")
        try:
            self._writer.write(connection, log_time_ns, cdr)
        except (WriterError, OSError) as err:  # a full disk, a file gone
            raise BagWriteError(f"cannot write {topic} into bag {self.partial}: {err}") from err
        self.count += 1

    def write_message(self, topic: str, log_time_ns: int, message: Any) -> None:
        msgtype = self._connections[topic].msgtype
        self.write(topic, log_time_ns, bytes(TYPESTORE.serialize_cdr(message, msgtype)))

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is not None and not issubclass(exc_type, KeyboardInterrupt):
            self.abort()
            return
        # normal end, or Ctrl-C / SIGTERM: keep every message written up to here in a bag that
        # opens; an interrupted one says so, and a second signal waits for the close
        if exc is not None:
            self._writer.set_custom_data(INTERRUPTED_KEY, interruption_name(exc))
        with deferred_interrupts():
            try:
                self._writer.close()
                _name_files_after(self.partial, self.path.name)
                self.partial.rename(self.path)
            except (WriterError, OSError) as err:
                shutil.rmtree(self.partial, ignore_errors=True)
                raise BagWriteError(f"cannot finish bag {self.path}: {err}") from err

    def abort(self) -> None:
        """Drop everything written so far (the partial directory is removed)."""
        with contextlib.suppress(WriterError, OSError, AttributeError):
            self._writer.close()
        shutil.rmtree(self.partial, ignore_errors=True)


def _name_files_after(directory: Path, name: str) -> None:
    """rosbags names the storage file after the directory it writes into, here the temporary
    ``<name>.partial``: give the file the bag's own name, in the metadata too, so a finished
    bag does not look unfinished."""
    old = f"{directory.name}.mcap"
    new = f"{name}.mcap"
    (directory / old).rename(directory / new)
    metadata = directory / "metadata.yaml"
    metadata.write_text(metadata.read_text().replace(old, new))


def message_types() -> Any:
    """The typestore's message classes (``types['sensor_msgs/msg/JointState']``)."""
    return TYPESTORE.types


def time_msg(ns: int) -> Any:
    """A builtin_interfaces/msg/Time of the typestore for ``ns`` nanoseconds."""
    return TYPESTORE.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
