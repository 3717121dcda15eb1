"""The estimator's ``momentum_observer`` method: samples and commanded torques in, per-joint
external-torque estimates and contact events out, with the interface of
:class:`transparency_ros.core.estimator.EstimatorPipeline` (the node serves either).

The commanded torque of each joint is the effort of /joint_commands (by joint name); with a
calibration, the one ``command_delay_s`` before the sample, limited to the URDF's effort limit,
less the calibrated offset. The torque of the interval between two samples is looked up when the
second arrives: a controller sends the command for an interval after the sample that opened
it, on another topic. A joint without a command has none applied (a passive joint). The
residual divided by its threshold (the calibration's, by speed, or a constant) drives the
Schmitt trigger, onset at 1. Bad samples are rejected and counted, never raised past the caller.
"""

from __future__ import annotations

import bisect
import math
import operator
from dataclasses import dataclass, field

import numpy as np

from transparency_ros.core.estimator import (
    ContactEvent,
    EstimatorError,
    JointEstimate,
    SampleRejectedError,
    SchmittDetector,
)
from transparency_ros.core.momentum_observer import RobotMomentumObserver
from transparency_ros.core.robot_calibration import Calibration, effort_limit, speed_band
from transparency_ros.core.robot_model import RobotModel

COMMAND_HISTORY = 256  # commands kept per joint (for the delay)


@dataclass
class ObserverPipeline:
    model: RobotModel
    gain_per_s: float
    detector: SchmittDetector
    calibration: Calibration | None = None
    threshold_nm: float = 0.5  # without a calibration
    rejected: dict[str, int] = field(default_factory=dict)
    samples: int = 0

    def __post_init__(self) -> None:
        base = self.model
        if self.calibration is not None:
            self.model = self.calibration.model(base)
            self.gain_per_s = self.calibration.gain_per_s
        if not (math.isfinite(self.threshold_nm) and self.threshold_nm > 0):
            raise EstimatorError(f"threshold_nm must be > 0, got {self.threshold_nm}")
        self.observer = RobotMomentumObserver(self.model, self.gain_per_s)
        self.limit = effort_limit(base)
        self.offset = (
            np.zeros(base.dof) if self.calibration is None else np.array(self.calibration.offset_nm)
        )
        self.delay_ns = 0 if self.calibration is None else round(
            self.calibration.command_delay_s * 1e9
        )  # fmt: skip
        self._commands: dict[str, tuple[list[int], list[float]]] = {}
        # the calibration's thresholds as one table (band, joint), converted once: the
        # sample path looks up the row of its speed's band
        self._thresholds = (
            None
            if self.calibration is None
            else np.asarray(self.calibration.thresholds_nm, dtype=float).T
        )
        # (the bands' edges too: a list searched as an array is converted on every sample)
        self._bands = (
            None
            if self.calibration is None
            else np.asarray(self.calibration.speed_bands_rad_s, dtype=float)
        )

    def reject(self, reason: str, detail: str) -> SampleRejectedError:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        return SampleRejectedError(reason, detail)

    def command(
        self,
        names: list[str],
        positions: list[float],
        velocities: list[float],
        stamp_ns: int | None = None,
        efforts: list[float] | None = None,
    ) -> None:
        """A /joint_commands message: its efforts are the commanded torques (by name)."""
        efforts = list(efforts or [])
        if not efforts:
            raise self.reject("no_effort", "the momentum observer needs commanded efforts")
        if len(efforts) != len(names) or len(set(names)) != len(names):
            raise self.reject("length_mismatch", f"{len(efforts)} efforts for names {names}")
        if not all(math.isfinite(e) for e in efforts):
            raise self.reject("not_finite", "NaN or inf in a command's effort")
        stamp = operator.index(stamp_ns) if stamp_ns is not None else self._latest_stamp()
        for name, effort in zip(names, efforts, strict=True):
            stamps, values = self._commands.setdefault(name, ([], []))
            if stamps and stamp < stamps[-1]:
                continue  # an older command than one held: the newer stands
            stamps.append(stamp)
            values.append(effort)
            if len(stamps) > COMMAND_HISTORY:
                del stamps[0], values[0]

    def latest_command_ns(self, joint: str) -> int | None:
        """The stamp of the newest command held for ``joint``, if any."""
        held = self._commands.get(joint)
        return held[0][-1] if held else None

    def _latest_stamp(self) -> int:
        last = self.observer.last_stamp_ns
        return last if last is not None else 0

    def _torque(self, stamp_ns: int) -> np.ndarray:
        """Each joint's applied torque at ``stamp_ns``: its command ``delay`` earlier."""
        at = stamp_ns - self.delay_ns
        tau = np.zeros(self.model.dof)
        for k, name in enumerate(self.model.joint_names):
            held = self._commands.get(name)
            if held is None:
                continue
            i = bisect.bisect_right(held[0], at) - 1
            tau[k] = held[1][max(i, 0)]
        return np.clip(tau, -self.limit, self.limit) - self.offset

    def sample(
        self, stamp_ns: int, names: list[str], positions: list[float], velocities: list[float]
    ) -> tuple[list[JointEstimate], list[ContactEvent]]:
        stamp_ns = operator.index(stamp_ns)
        if len(positions) != len(names) or len(velocities) != len(names):
            raise self.reject(
                "length_mismatch",
                f"{len(positions)} positions, {len(velocities)} velocities for {len(names)} names"
                " (the momentum observer needs both)",
            )
        index = {n: i for i, n in enumerate(names)}
        missing = [j for j in self.model.joint_names if j not in index]
        if missing:
            raise self.reject("missing_joint", f"{missing} of the robot model not in {names}")
        order = [index[j] for j in self.model.joint_names]
        q = np.array([positions[i] for i in order])
        v = np.array([velocities[i] for i in order])
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise self.reject("not_finite", "NaN or inf in a joint state")
        last = self.observer.last_stamp_ns
        # the interval since the last sample is integrated with the command that held over
        # it, looked up now: a controller sends it after the sample that opened the interval
        applied = self._torque(last) if last is not None else np.zeros(self.model.dof)
        try:
            r = self.observer.step(stamp_ns, q, v, applied)
        except EstimatorError as err:
            raise self.reject("stamp_not_increasing", str(err)) from err
        if self._bands is not None and self._thresholds is not None:
            threshold = self._thresholds[speed_band(self._bands, v)[0]]
        else:
            threshold = np.full(self.model.dof, self.threshold_nm)
        self.samples += 1
        estimates: list[JointEstimate] = []
        events: list[ContactEvent] = []
        for k, joint in enumerate(self.model.joint_names):
            share = float(abs(r[k]) / threshold[k]) if math.isfinite(threshold[k]) else 0.0
            estimates.append(JointEstimate(joint, stamp_ns, share, float(r[k])))
            events += self.detector.update(joint, stamp_ns, share, float(r[k]))
        return estimates, events

    def reset(self) -> None:
        self.detector.reset()
        self.observer.reset()


@dataclass
class AwaitingModel:
    """The ``momentum_observer`` method before its robot model has come (the node takes the
    URDF from /robot_description when its parameter is empty, as ros2_control's controller
    manager does): every sample and command is rejected and counted, ``no_robot_description``."""

    rejected: dict[str, int] = field(default_factory=dict)
    samples: int = 0

    def reject(self, reason: str, detail: str) -> SampleRejectedError:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        return SampleRejectedError(reason, detail)

    def _waiting(self) -> SampleRejectedError:
        return self.reject("no_robot_description", "no robot model yet (/robot_description)")

    def command(self, *_args: object, **_kwargs: object) -> None:
        raise self._waiting()

    def sample(self, *_args: object) -> tuple[list[JointEstimate], list[ContactEvent]]:
        raise self._waiting()

    def reset(self) -> None:
        """Nothing to clear before the model comes."""
