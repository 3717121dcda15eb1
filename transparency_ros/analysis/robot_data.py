"""Multi-joint recordings for contact detection on robots: joint positions, velocities, the
commanded torque and, where a recording has them, the true external torques (labels).

Read from CSV (plain or ``.xz``) with one column per quantity and joint, numbered from 1 in the
model's joint order, as the DFKI double pendulum's recordings are (``pos_meas1``, ``vel_meas1``,
``tau_con1``, ``tau_pert1``, ...); :class:`Columns` names the patterns. Rows whose stamp does not
increase are dropped (noted); a NaN in a used column is an error naming the file, row and column.

Or from a rosbag2 bag (:func:`read_joint_bag`): /joint_states (positions and velocities by joint
name) and the efforts of /joint_commands, each sample taking the latest command at or before
its stamp, as the estimator node does.
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


@dataclass(frozen=True)
class Columns:
    """Column name patterns; ``{}`` is the joint's number (1, 2, ...)."""

    time: str = "time"
    position: str = "pos_meas{}"
    velocity: str = "vel_meas{}"
    torque: str = "tau_con{}"  # the controller's command: what the model is driven by
    label: str | None = "tau_pert{}"  # true external torque, where recorded
    desired: str | None = "pos_des{}"  # the desired position, where recorded (eq. (1))


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

    def reordered(self, order: npt.NDArray[np.int64], joints: Sequence[str]) -> JointRecording:
        """The same run with its joint columns taken in ``order`` (named ``joints``)."""
        if tuple(joints) == self.joints:
            return self

        def take(a: FloatArray | None) -> FloatArray | None:
            return None if a is None else a[:, order]

        return JointRecording(
            self.name, self.stamps_ns, tuple(joints), self.position[:, order],
            self.velocity[:, order], self.torque[:, order], take(self.label),
            take(self.desired), list(self.notes),
        )  # fmt: skip

    @property
    def duration_s(self) -> float:
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9


def read_joint_csv(
    path: str | Path, joints: Sequence[str], columns: Columns | None = None
) -> JointRecording:
    """The recording in ``path``; column k (1-based) of each pattern is ``joints[k - 1]``."""
    cols = columns or Columns()
    p = Path(path)
    try:
        if p.suffix == ".xz":
            with lzma.open(p, "rb") as f:
                raw = f.read()
        else:
            raw = p.read_bytes()
    except (OSError, lzma.LZMAError) as err:
        raise ConfigError(f"{p}: cannot read: {err}") from err
    reader = csv.reader(io.StringIO(raw.decode("utf-8", errors="replace")))
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

    t = column(cols.time)
    stamps = np.round((t - t[0]) * 1e9).astype(np.int64)
    keep = np.r_[True, np.diff(stamps) > 0]
    notes = []
    if not keep.all():
        # a stamp repeated by the logger: the later row of the pair is dropped
        keep = np.r_[True, stamps[1:] > np.maximum.accumulate(stamps)[:-1]]
        dropped = np.count_nonzero(~keep)
        notes.append(f"{p.name}: {dropped} rows whose time does not increase dropped")
    position, velocity = per_joint(cols.position), per_joint(cols.velocity)
    torque = per_joint(cols.torque)
    label, desired = optional(cols.label), optional(cols.desired)
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
    )


def read_joint_bag(path: str | Path, joints: Sequence[str]) -> JointRecording:
    """The run in bag ``path``: /joint_states of ``joints`` with the efforts of /joint_commands
    held from each command's stamp (none before the first: 0)."""
    from transparency_ros.bag.reader import open_bag  # noqa: PLC0415

    with open_bag(path) as bag:
        return _joint_bag(bag, path, joints)


def _joint_bag(bag: Any, path: str | Path, joints: Sequence[str]) -> JointRecording:
    from transparency_ros.bag.reader import JOINT_STATE, joint_series  # noqa: PLC0415

    states = [joint_series(bag, "/joint_states", j) for j in joints]
    missing = [j for j, s in zip(joints, states, strict=True) if s.stamp_ns.size == 0]
    if missing:
        raise ConfigError(f"{path}: /joint_states has no joint {missing}")
    stamps = states[0].stamp_ns
    if any(s.stamp_ns.size != stamps.size or np.any(s.stamp_ns != stamps) for s in states):
        raise ConfigError(f"{path}: the joints of /joint_states are not sampled together")
    torque = np.zeros((stamps.size, len(joints)))
    if "/joint_commands" in bag.topics:
        bag.require_topic("/joint_commands", JOINT_STATE)
        for k, joint in enumerate(joints):
            cmd = joint_series(bag, "/joint_commands", joint)
            ok = np.isfinite(cmd.effort)
            at = np.searchsorted(cmd.stamp_ns[ok], stamps, side="right") - 1
            held = cmd.effort[ok]
            if held.size:
                torque[:, k] = np.where(at >= 0, held[np.clip(at, 0, None)], 0.0)
    notes = [] if "/joint_commands" in bag.topics else [f"{path}: no /joint_commands: no torque"]
    position = np.stack([s.position for s in states], axis=1)
    velocity = np.stack([s.velocity for s in states], axis=1)
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity))):
        raise ConfigError(f"{path}: /joint_states needs finite positions and velocities")
    return JointRecording(
        Path(path).name, stamps - stamps[0], tuple(joints), position, velocity, torque,
        notes=notes,
    )  # fmt: skip
