"""Multi-joint recordings for contact detection on robots: joint positions, velocities, the
commanded torque and, where a recording has them, the true external torques (labels).

Read from CSV (plain or ``.xz``) with one column per quantity and joint, numbered from 1 in the
model's joint order, as the DFKI double pendulum's recordings are (``pos_meas1``, ``vel_meas1``,
``tau_con1``, ``tau_pert1``, ...); :class:`Columns` names the patterns. Rows whose stamp does not
increase are dropped (noted); a NaN in a used column is an error naming the file, row and column.

Or from a rosbag2 bag (:func:`read_joint_bag`): /joint_states (positions and velocities by joint
name; efforts, where recorded, as the motor-measured torque) and /joint_commands (efforts; the
desired positions where recorded), each sample taking the latest command at or before its
stamp, as the estimator node does; the true external torques, where a bag has them, on
:data:`LABEL_TOPIC`. :func:`write_joint_bag` writes a recording so (``transparency import-csv
--joints``); read back, it is the same recording.
"""

from __future__ import annotations

import csv
import io
import lzma
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from transparency_ros.core.errors import ConfigError

FloatArray = npt.NDArray[np.float64]

LABEL_TOPIC = "/true_external_effort"  # sensor_msgs/JointState, effort = the true external torque


@dataclass(frozen=True)
class Columns:
    """Column name patterns; ``{}`` is the joint's number (1, 2, ...)."""

    time: str = "time"
    position: str = "pos_meas{}"
    velocity: str = "vel_meas{}"
    torque: str = "tau_con{}"  # the controller's command: what the model is driven by
    label: str | None = "tau_pert{}"  # true external torque, where recorded
    desired: str | None = "pos_des{}"  # the desired position, where recorded (eq. (1))
    measured: str | None = None  # the motor-measured torque, where recorded (not used to detect)

    @classmethod
    def parse(cls, text: str, **optional: str | None) -> Columns:
        """``time=time,position=pos_meas{},...`` (any of the four required patterns; the rest
        keep their defaults) with the optional patterns given as keywords."""
        known = {"time", "position", "velocity", "torque"}
        values: dict[str, str | None] = {}
        for item in text.split(","):
            key, _, value = item.strip().partition("=")
            if key not in known or not value:
                raise ConfigError(f"--columns: {item!r} is not one of {sorted(known)}=PATTERN")
            values[key] = value
        return cls(**values, **optional)  # type: ignore[arg-type]


@dataclass
class JointRecording:
    """One run; arrays are (samples, joints) in the order of ``joints``."""

    name: str
    stamps_ns: npt.NDArray[np.int64]
    joints: tuple[str, ...]
    position: FloatArray
    velocity: FloatArray
    torque: FloatArray
    label: FloatArray | None = None
    desired: FloatArray | None = None
    notes: list[str] = field(default_factory=list)
    measured: FloatArray | None = None

    def reordered(self, order: npt.NDArray[np.int64], joints: Sequence[str]) -> JointRecording:
        """The same run with its joint columns taken in ``order`` (named ``joints``)."""
        if tuple(joints) == self.joints:
            return self

        def take(a: FloatArray | None) -> FloatArray | None:
            return None if a is None else a[:, order]

        return JointRecording(
            self.name, self.stamps_ns, tuple(joints), self.position[:, order],
            self.velocity[:, order], self.torque[:, order], take(self.label),
            take(self.desired), list(self.notes), take(self.measured),
        )  # fmt: skip

    @property
    def duration_s(self) -> float:
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9


def read_text(path: Path) -> str:
    """The text of a file, plain or ``.xz``-compressed; a ConfigError naming it if unreadable."""
    try:
        if path.suffix == ".xz":
            with lzma.open(path, "rb") as f:
                raw = f.read()
        else:
            raw = path.read_bytes()
    except (OSError, lzma.LZMAError) as err:
        raise ConfigError(f"{path}: cannot read: {err}") from err
    return raw.decode("utf-8", errors="replace")


def check_time(path: Path, name: str, t: FloatArray, *, repeats: bool = False) -> None:
    """A time column that goes backwards (or, unless ``repeats``, repeats a value) is refused,
    naming the first such row of the file (the header is row 1)."""
    steps = np.diff(t)
    bad = np.flatnonzero(steps < 0 if repeats else steps <= 0)
    if bad.size:
        k = int(bad[0])
        how = "repeats" if steps[k] == 0 else "goes backwards"
        raise ConfigError(
            f"{path}: time column {name!r} {how} at row {k + 3}: {t[k + 1]:g} after {t[k]:g} "
            f"({bad.size} such row{'s' if bad.size > 1 else ''})"
        )


def read_joint_csv(
    path: str | Path, joints: Sequence[str], columns: Columns | None = None, *, exact: bool = False
) -> JointRecording:
    """The recording in ``path``; column k (1-based) of each pattern is ``joints[k - 1]``.
    ``exact``: a file with columns for more joints than ``joints`` is refused (the joints came
    from a URDF, not from the user: most likely another robot's)."""
    cols = columns or Columns()
    p = Path(path)
    reader = csv.reader(io.StringIO(read_text(p)))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration as err:
        raise ConfigError(f"{p}: empty file") from err
    rows = [r for r in reader if r]
    if len(rows) < 2:
        raise ConfigError(f"{p}: fewer than 2 data rows")
    index = {h: i for i, h in enumerate(header)}

    def column(name: str) -> FloatArray:
        if name not in index:
            raise ConfigError(f"{p}: no column {name!r} (columns: {header})")
        i = index[name]
        try:
            values = np.array([float(r[i]) for r in rows])
        except (ValueError, IndexError) as err:
            raise ConfigError(f"{p}: column {name!r}: {err}") from err
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ConfigError(f"{p}: column {name!r} is not a finite number in row {bad[0] + 2}")
        return values

    def per_joint(pattern: str) -> FloatArray:
        return np.stack([column(pattern.format(k + 1)) for k in range(len(joints))], axis=1)

    def optional(pattern: str | None) -> FloatArray | None:
        if pattern is None or pattern.format(1) not in index:
            return None
        return per_joint(pattern)

    # (a pattern without the number names one column: nothing more to find)
    more = range(len(joints) + 1, len(header) + 2) if exact and "{}" in cols.position else ()
    extra = [name for k in more if (name := cols.position.format(k)) in index]
    if extra:
        raise ConfigError(
            f"{p}: columns for {len(joints) + len(extra)} joints ({cols.position.format(1)} .. "
            f"{extra[-1]}), the URDF has {len(joints)} ({', '.join(joints)}): another robot's "
            "URDF? (--joints names the ones to use)"
        )
    t = column(cols.time)
    # a repeated stamp is a logger's habit (dropped below); going back is not
    check_time(p, cols.time, t, repeats=True)
    stamps = np.round((t - t[0]) * 1e9).astype(np.int64)
    keep = np.r_[True, np.diff(stamps) > 0]
    notes = []
    if not keep.all():
        # a stamp repeated by the logger: the later row of the pair is dropped
        keep = np.r_[True, stamps[1:] > np.maximum.accumulate(stamps)[:-1]]
        dropped = np.count_nonzero(~keep)
        rows_ = "row" if dropped == 1 else "rows"
        notes.append(f"{p.name}: {dropped} {rows_} whose time does not increase dropped")
    position, velocity = per_joint(cols.position), per_joint(cols.velocity)
    torque = per_joint(cols.torque)
    label, desired = optional(cols.label), optional(cols.desired)
    measured = optional(cols.measured)
    return JointRecording(
        name=p.name.split(".")[0],
        stamps_ns=stamps[keep],
        joints=tuple(joints),
        position=position[keep],
        velocity=velocity[keep],
        torque=torque[keep],
        label=None if label is None else label[keep],
        desired=None if desired is None else desired[keep],
        notes=notes,
        measured=None if measured is None else measured[keep],
    )


def read_joint_bag(
    path: str | Path, joints: Sequence[str], labels: str | None = None
) -> JointRecording:
    """The run in bag ``path``: /joint_states of ``joints`` with the efforts of /joint_commands
    held from each command's stamp (none before the first: 0); with ``labels`` (a topic), the
    true external torques held likewise."""
    from transparency_ros.bag.reader import open_bag  # noqa: PLC0415

    with open_bag(path) as bag:
        return _joint_bag(bag, path, joints, labels)


def _held(bag: Any, topic: str, joints: Sequence[str], stamps: Any, field: str) -> FloatArray:
    """Each joint's ``field`` of ``topic`` (a JointState) held from its stamp: at every one of
    ``stamps`` the latest finite value at or before it (0 before the first, NaN if none)."""
    from transparency_ros.bag.reader import joint_series  # noqa: PLC0415

    out = np.full((stamps.size, len(joints)), np.nan)
    for k, joint in enumerate(joints):
        series = joint_series(bag, topic, joint)
        values = getattr(series, field)
        ok = np.isfinite(values)
        if ok.any():
            at = np.searchsorted(series.stamp_ns[ok], stamps, side="right") - 1
            out[:, k] = np.where(at >= 0, values[ok][np.clip(at, 0, None)], 0.0)
    return out


def _joint_bag(
    bag: Any, path: str | Path, joints: Sequence[str], labels: str | None = None
) -> JointRecording:
    from transparency_ros.bag.reader import JOINT_STATE, joint_series  # noqa: PLC0415

    states = [joint_series(bag, "/joint_states", j) for j in joints]
    missing = [j for j, s in zip(joints, states, strict=True) if s.stamp_ns.size == 0]
    if missing:
        raise ConfigError(f"{path}: /joint_states has no joint {missing}")
    stamps = states[0].stamp_ns
    if any(s.stamp_ns.size != stamps.size or np.any(s.stamp_ns != stamps) for s in states):
        raise ConfigError(f"{path}: the joints of /joint_states are not sampled together")
    notes = []
    torque = np.zeros((stamps.size, len(joints)))
    desired = None
    if "/joint_commands" in bag.topics:
        bag.require_topic("/joint_commands", JOINT_STATE)
        torque = np.nan_to_num(_held(bag, "/joint_commands", joints, stamps, "effort"))
        desired = _held(bag, "/joint_commands", joints, stamps, "position")
        desired = desired if np.all(np.isfinite(desired)) else None
    else:
        notes.append(f"{path}: no /joint_commands: no torque")
    label = None
    if labels is not None and labels not in bag.topics:
        notes.append(f"{path}: no {labels}: no true external torques (a run without contact)")
    elif labels is not None:
        bag.require_topic(labels, JOINT_STATE)
        label = _held(bag, labels, joints, stamps, "effort")
        lacking = [j for k, j in enumerate(joints) if not np.isfinite(label[:, k]).all()]
        if lacking:
            raise ConfigError(f"{path}: {labels} has no effort of joint {lacking}")
    position = np.stack([s.position for s in states], axis=1)
    velocity = np.stack([s.velocity for s in states], axis=1)
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity))):
        raise ConfigError(f"{path}: /joint_states needs finite positions and velocities")
    measured = np.stack([s.effort for s in states], axis=1)
    return JointRecording(
        Path(path).name.split(".")[0], stamps - stamps[0], tuple(joints), position, velocity,
        torque, label, desired, notes,
        measured if np.all(np.isfinite(measured)) else None,
    )  # fmt: skip


def write_joint_bag(
    path: str | Path, rec: JointRecording, source: str = "", start_ns: int = 0
) -> Path:
    """``rec`` as a robot's driver and controller record it, into a new bag ``path`` (MCAP,
    written atomically): /joint_states (position, velocity; effort = the measured torque where
    ``rec`` has it), /joint_commands (effort = the command; position = the desired position
    where it has it) and, where it has labels, :data:`LABEL_TOPIC`. Stamps start at
    ``start_ns``."""
    from transparency_ros.bag.writer import BagWriter, message_types, time_msg  # noqa: PLC0415

    types = message_types()
    empty = np.empty(0)

    def joint_state(ns: int, **arrays: FloatArray | None) -> object:
        header = types["std_msgs/msg/Header"](stamp=time_msg(ns), frame_id="")
        fields = {
            k: empty if arrays.get(k) is None else arrays[k]
            for k in ("position", "velocity", "effort")
        }
        return types["sensor_msgs/msg/JointState"](header=header, name=list(rec.joints), **fields)

    custom = {"transparency.trial": "robot", "transparency.source": source or rec.name}
    with BagWriter(Path(path), custom) as bag:
        bag.add("/joint_states", "sensor_msgs/msg/JointState")
        bag.add("/joint_commands", "sensor_msgs/msg/JointState")
        if rec.label is not None:
            bag.add(LABEL_TOPIC, "sensor_msgs/msg/JointState")

        def row(a: FloatArray | None, k: int) -> FloatArray | None:
            return None if a is None else a[k]

        for k, ns in enumerate((rec.stamps_ns + start_ns).tolist()):
            measured = row(rec.measured, k)
            state = joint_state(ns, position=rec.position[k], velocity=rec.velocity[k],
                                effort=measured)  # fmt: skip
            bag.write_message("/joint_states", ns, state)
            # the command computed from this sample, logged just after it
            command = joint_state(ns, position=row(rec.desired, k), effort=rec.torque[k])
            bag.write_message("/joint_commands", ns + 1, command)
            if rec.label is not None:
                bag.write_message(LABEL_TOPIC, ns + 1, joint_state(ns, effort=rec.label[k]))
    return Path(path)
