"""Contact detection on a robot's recordings, offline, and its score against labels.

Three detectors, run on the same recordings and scored alike:

* ``momentum_observer`` with a calibration (:mod:`robot_calibration`): the calibrated model, the
  command delayed as calibrated, thresholds that depend on the speed;
* ``textbook``: the generalized-momentum observer with the URDF's model as it is and one
  threshold per joint just above its largest residual on the recordings without contact;
* ``position_error``: eq. (1)'s signal, the desired minus the measured position, with one
  threshold per joint likewise (only where the recordings carry a desired position).

A detection is an onset of the Schmitt trigger of the live estimator
(:class:`transparency_ros.core.estimator.SchmittDetector`) on the residual divided by its
threshold (onset at 1, release at 0.5). Scoring per joint: a labelled pulse is a run of samples
where the true external torque is at least ``PULSE_LEVEL_NM``; it is found when an onset falls
between its start and ``GRACE_S`` after its end; the delay is counted from the first sample at
half the pulse's peak. Any other onset is a false alarm; onsets within ``ALARM_MERGE_S`` of the
previous one are one alarm. A detector that alarms often finds pulses by chance: :func:`by_chance`
scores the same onsets against the labels moved in time, the recall to beat.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from transparency_ros.analysis.robot_calibration import applied, run_pipeline
from transparency_ros.analysis.robot_data import FloatArray, JointRecording
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.estimator import DetectorSettings, EventKind, SchmittDetector
from transparency_ros.core.momentum_observer import RobotMomentumObserver
from transparency_ros.core.robot_calibration import Calibration, effort_limit
from transparency_ros.core.robot_model import RobotModel

PULSE_LEVEL_NM = 0.05
GRACE_S = 0.1
ALARM_MERGE_S = 0.2
RELEASE_RATIO = 0.5  # a contact ends below this share of the threshold (as in the node)
TEXTBOOK_MARGIN = 1.01  # "just above" the largest residual without contact
CHANCE_SHIFTS_S = (1.3, 2.6, 3.9)  # the labels moved in time (circularly within a recording)


@dataclass
class Detection:
    recording: str
    joints: tuple[str, ...]
    t_s: FloatArray
    residual: FloatArray  # (samples, joints) [N m], or [rad] for the position error
    threshold: FloatArray  # (samples, joints); inf where the detector does not judge
    onsets_s: list[list[float]]  # per joint


@dataclass
class Pulse:
    joint: int
    start_s: float
    half_s: float  # first sample at half the peak
    end_s: float
    peak: float


@dataclass(frozen=True)
class Episode:
    """One contact as a detector saw it on one joint."""

    onset_s: float  # the stamp of the sample that crossed the threshold
    release_s: float | None  # the first sample back below half of it (None: still on at the end)
    peak_residual: float  # the residual of largest magnitude in between, signed [N m] or [rad]


@dataclass(frozen=True)
class MissedPulse:
    recording: str
    joint: str
    start_s: float
    half_s: float  # first sample at half the peak
    end_s: float
    peak_nm: float


@dataclass
class Score:
    pulses: int = 0
    found: int = 0
    false_alarms: int = 0
    minutes: float = 0.0
    judged_share: float = 0.0  # of the samples, where the threshold is finite
    delays_s: list[float] = field(default_factory=list)
    missed: list[MissedPulse] = field(default_factory=list)

    @property
    def recall(self) -> float:
        return self.found / self.pulses if self.pulses else float("nan")

    @property
    def alarms_per_minute(self) -> float:
        return self.false_alarms / self.minutes if self.minutes else float("nan")

    def delay_s(self, q: float) -> float:
        return float(np.percentile(self.delays_s, q)) if self.delays_s else float("nan")


def in_model_order(model: RobotModel, recording: JointRecording) -> JointRecording:
    """``recording`` with its joints in the model's order (a clear error for one missing)."""
    order = model.index(recording.joints, where=recording.name)
    return recording.reordered(order, model.joint_names)


def observer_residual(
    model: RobotModel, recording: JointRecording, gain_per_s: float, torque: FloatArray
) -> FloatArray:
    """The observer's residual, (samples, joints); ``recording`` in the model's joint order."""
    return RobotMomentumObserver(model, gain_per_s).run(
        recording.stamps_ns, recording.position, recording.velocity, torque
    )


def calibrated(base: RobotModel, calibration: Calibration, recording: JointRecording) -> Detection:
    """The calibrated detector on ``recording`` (in the model's joint order), as the node
    runs it."""
    residual, onsets = run_pipeline(base, calibration, recording)
    t = np.asarray(recording.stamps_ns * 1e-9, dtype=np.float64)
    threshold = calibration.threshold(recording.velocity)
    return Detection(recording.name, recording.joints, t, residual, threshold, onsets)


def textbook_residual(
    model: RobotModel, recording: JointRecording, gain_per_s: float
) -> FloatArray:
    return observer_residual(
        model, recording, gain_per_s, applied(recording, 0.0, effort_limit(model))
    )


def position_error(recording: JointRecording) -> FloatArray:
    if recording.desired is None:
        raise ConfigError(f"{recording.name}: no desired position recorded (eq. (1) needs it)")
    return np.asarray(recording.desired - recording.position, dtype=np.float64)


def constant_thresholds(residuals: Sequence[FloatArray]) -> FloatArray:
    """Per joint, just above the largest residual of the recordings without contact."""
    out: FloatArray = TEXTBOOK_MARGIN * np.max([np.abs(r).max(axis=0) for r in residuals], axis=0)
    return out


def with_threshold(recording: JointRecording, residual: FloatArray, per_joint: FloatArray
                   ) -> Detection:  # fmt: skip
    return detect(recording, residual, np.broadcast_to(per_joint, residual.shape))


def detect(recording: JointRecording, residual: FloatArray, threshold: FloatArray) -> Detection:
    """The live estimator's Schmitt trigger on ``residual`` / ``threshold`` (both (samples,
    joints); a threshold of inf never fires)."""
    settings = DetectorSettings(contact_onset=1.0, contact_release=RELEASE_RATIO)
    detector = SchmittDetector(default=settings)
    onsets: list[list[float]] = [[] for _ in recording.joints]
    ratio = np.abs(residual) / threshold
    for k, stamp in enumerate(recording.stamps_ns):
        for j, joint in enumerate(recording.joints):
            for event in detector.update(joint, int(stamp), float(ratio[k, j]), 0.0):
                if event.kind is EventKind.CONTACT_ONSET:
                    onsets[j].append(event.stamp_ns * 1e-9)
    t = np.asarray(recording.stamps_ns * 1e-9, dtype=np.float64)
    return Detection(recording.name, recording.joints, t, residual, threshold, onsets)


def episodes(det: Detection) -> list[list[Episode]]:
    """Per joint, each onset with its release and peak: the release is the first sample after
    the onset where |residual| falls to ``RELEASE_RATIO`` of the threshold, the level both
    detectors here release at (a threshold of inf, where the detector does not judge, releases
    too)."""
    out: list[list[Episode]] = []
    for j, onsets in enumerate(det.onsets_s):
        with np.errstate(invalid="ignore"):
            ratio = np.abs(det.residual[:, j]) / det.threshold[:, j]
        found = []
        for onset in onsets:
            k0 = int(np.searchsorted(det.t_s, onset))
            below = np.flatnonzero(ratio[k0 + 1 :] <= RELEASE_RATIO)
            end = k0 + 1 + int(below[0]) if below.size else None
            span = det.residual[k0 : (end if end is not None else det.t_s.size), j]
            peak = float(span[np.argmax(np.abs(span))]) if span.size else float("nan")
            release = float(det.t_s[end]) if end is not None else None
            found.append(Episode(float(onset), release, peak))
        out.append(found)
    return out


def pulses(recording: JointRecording) -> list[Pulse]:
    if recording.label is None:
        return []
    t = recording.stamps_ns * 1e-9
    out = []
    for j in range(recording.label.shape[1]):
        size = np.abs(recording.label[:, j])
        on = size >= PULSE_LEVEL_NM
        starts = np.flatnonzero(on & ~np.r_[False, on[:-1]])
        ends = np.flatnonzero(on & ~np.r_[on[1:], False])
        for s, e in zip(starts, ends, strict=True):
            peak = float(size[s : e + 1].max())
            half = s + int(np.argmax(size[s : e + 1] >= peak / 2))
            out.append(Pulse(j, float(t[s]), float(t[half]), float(t[e]), peak))
    return out


def score(
    detections: Sequence[Detection],
    recordings: Sequence[JointRecording],
    joint: int | None = None,
) -> Score:
    """Pulses found, false alarms and delays over ``recordings`` (all joints, or one)."""
    total = Score()
    judged = samples = 0
    for det, rec in zip(detections, recordings, strict=True):
        total.minutes += rec.duration_s / 60
        judged += int(np.count_nonzero(np.all(np.isfinite(det.threshold), axis=1)))
        samples += det.t_s.size
        labelled = pulses(rec)
        for j, onsets in enumerate(det.onsets_s):
            if joint is not None and j != joint:
                continue
            times = np.array(onsets)
            used = np.zeros(times.size, dtype=bool)
            for p in (p for p in labelled if p.joint == j):
                total.pulses += 1
                hit = (times >= p.start_s) & (times <= p.end_s + GRACE_S)
                if hit.any():
                    total.found += 1
                    total.delays_s.append(max(0.0, float(times[hit][0]) - p.half_s))
                    used |= hit
                else:
                    total.missed.append(MissedPulse(
                        rec.name, rec.joints[j], p.start_s, p.half_s, p.end_s, p.peak))  # fmt: skip
            alarms = times[~used]
            if alarms.size:
                total.false_alarms += 1 + int(np.count_nonzero(np.diff(alarms) > ALARM_MERGE_S))
    total.judged_share = judged / samples if samples else float("nan")
    return total


def by_chance(
    detections: Sequence[Detection],
    recordings: Sequence[JointRecording],
    joint: int | None = None,
    shifts_s: Sequence[float] = CHANCE_SHIFTS_S,
) -> Score:
    """What these onsets find by chance: scored against each recording's labels moved
    ``shifts_s`` later (wrapping round), pulses, those found and alarms summed over the
    shifts. Its recall is the one a detector must beat to have seen anything."""
    scores = []
    for shift in shifts_s:
        moved = []
        for rec in recordings:
            if rec.label is None:
                moved.append(rec)
                continue
            step = float(np.median(np.diff(rec.stamps_ns))) * 1e-9
            moved.append(replace(rec, label=np.roll(rec.label, round(shift / step), axis=0)))
        scores.append(score(detections, moved, joint))
    return pooled(scores)


def pooled(scores: Sequence[Score]) -> Score:
    """Several scores as one: counts, minutes, delays and misses summed, the judged share
    averaged."""
    out = Score()
    for s in scores:
        out.pulses += s.pulses
        out.found += s.found
        out.false_alarms += s.false_alarms
        out.minutes += s.minutes
        out.delays_s += s.delays_s
        out.missed += s.missed
    out.judged_share = float(np.mean([s.judged_share for s in scores])) if scores else 0.0
    return out
