"""The sensitivity assay: a contact detector's minimum detectable external torque per joint.

The robot's counterpart of the paper's minimum detectable energy. Measured on runs *without*
contact that the detector was not calibrated on: rectangular pulses are added to the recorded
command. The recorded motion is exactly what the robot would have done had an external torque
``p`` acted while its motors applied ``command - p``, so a detector that takes the command as
the applied torque sees a contact of ``p`` on top of the motion's own residual -- no simulator
in between, and the residual the pulses must stand out of is the real one.

The operating point is the detector's own: per joint, its threshold profile (constant for the
textbook observer, growing with speed for a calibration) scaled by the smallest factor at which
the same runs, without pulses, give at most ``alarms_per_minute`` false alarms. At that scale,
the minimum detectable torque is the smallest pulse amplitude of which at least ``recall`` of
the pulses are found (an onset between a pulse's start and 0.1 s after its end, as
:func:`robot_detect.score` counts), found by bisection on a log scale. Pulses last
``widths_s`` (drawn uniformly), one per joint per ``spacing_s`` at a random place in it, of
random sign; every joint carries its own train (the momentum observer's residual of one joint
does not see another joint's command, so the trains do not disturb each other).

The scale is chosen on the very runs the recall is measured on: the figure is the best this
detector can do at that false-alarm rate there, the same for every detector compared.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from transparency_ros.analysis import robot_detect as rd
from transparency_ros.analysis.discrepancy.robot_shooting import (
    carrying,
    command_path,
    felt_torque,
)
from transparency_ros.analysis.robot_calibration import MARGIN, run_pipeline
from transparency_ros.analysis.robot_data import FloatArray, JointRecording
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.robot_calibration import (
    SPEED_BANDS,
    Calibration,
    at_speed,
    banded_thresholds,
)
from transparency_ros.core.robot_model import RobotModel

SETTLE_S = 0.5  # no pulse before this: the observer starts from rest
RECOVERY_S = 0.3  # at least this between a pulse's end and the next pulse's slot
SCALE_STEPS = 12  # bisections of the threshold scale (log, 1000:1 range): to 0.2 %
AMPLITUDE_STEPS = 8  # bisections of the amplitude (log, 100:1 range): to 2 %


@dataclass(frozen=True)
class AssaySettings:
    widths_s: tuple[float, float] = (0.05, 0.1)
    spacing_s: float = 1.0
    placements: int = 2  # pulse trains per run, placed independently
    recall: float = 0.9
    alarms_per_minute: float = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        lo, hi = self.widths_s
        if not 0 < lo <= hi:
            raise ConfigError(f"pulse widths {self.widths_s}: need 0 < shortest <= longest [s]")
        if self.spacing_s < hi + RECOVERY_S:
            raise ConfigError(
                f"pulse spacing {self.spacing_s} s: at least the longest pulse plus "
                f"{RECOVERY_S} s to recover"
            )
        if self.placements < 1:
            raise ConfigError(f"placements {self.placements}: at least 1")
        if not 0 < self.recall <= 1:
            raise ConfigError(f"recall {self.recall}: a share in (0, 1]")
        if not self.alarms_per_minute >= 0:
            raise ConfigError(f"alarms per minute {self.alarms_per_minute}: not negative")


@dataclass(frozen=True)
class Assayed:
    """A detector as the assay needs it, for the runs of one calibration fold."""

    residual: Callable[[JointRecording], FloatArray]  # (samples, joints) [N m]
    threshold: Callable[[JointRecording], FloatArray]  # its profile, (samples, joints) [N m]


@dataclass
class JointSensitivity:
    joint: str
    threshold_scale: float  # the profile's factor at the operating point
    threshold_nm: float  # there, the median over the runs' samples (where it judges)
    alarms_per_minute: float  # at that scale, on the runs without pulses
    minutes: float  # of runs the false alarms were counted on
    min_torque_nm: float | None  # None: not reached below ``largest_tried_nm``
    recall: float  # at ``min_torque_nm`` (or at the largest tried)
    pulses: int  # per amplitude tried
    delay_median_s: float  # at ``min_torque_nm``
    largest_tried_nm: float
    tried: list[tuple[float, float]] = field(default_factory=list)  # (amplitude, recall)


def pulse_labels(recording: JointRecording, settings: AssaySettings, placement: int
                 ) -> FloatArray:  # fmt: skip
    """Unit pulses (+-1 where a pulse acts, else 0), (samples, joints), the same for the same
    run name, placement and seed."""
    key = [settings.seed, placement, *recording.name.encode()]
    rng = np.random.default_rng(key)
    t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
    out: FloatArray = np.zeros(recording.position.shape)
    lo, hi = settings.widths_s
    slots = int((t[-1] - SETTLE_S) // settings.spacing_s)
    for j in range(recording.position.shape[1]):
        for i in range(slots):
            width = rng.uniform(lo, hi)
            start = (
                SETTLE_S
                + i * settings.spacing_s
                + rng.uniform(0.0, settings.spacing_s - width - RECOVERY_S)
            )
            sign = 1.0 if rng.random() < 0.5 else -1.0
            out[(t >= start) & (t < start + width), j] = sign
    return out


def with_pulses(recording: JointRecording, labels: FloatArray) -> JointRecording:
    """``recording`` as if the external torques ``labels`` had acted: the command less them,
    the labels the truth."""
    return replace(recording, torque=recording.torque - labels, label=labels)


def _detections(cases: Sequence[tuple[Assayed, JointRecording]], scale: FloatArray,
                residuals: Sequence[FloatArray] | None = None) -> list[rd.Detection]:  # fmt: skip
    out = []
    for k, (det, rec) in enumerate(cases):
        residual = det.residual(rec) if residuals is None else residuals[k]
        out.append(rd.detect(rec, residual, det.threshold(rec) * scale))
    return out


def _alarms(cases: Sequence[tuple[Assayed, JointRecording]], residuals: Sequence[FloatArray],
            scale: FloatArray) -> tuple[FloatArray, float]:  # fmt: skip
    """Per joint, false alarms per minute of ``cases`` (no pulses) at ``scale``, and minutes."""
    clean = [replace(rec, label=None) for _, rec in cases]
    detections = _detections(cases, scale, residuals)
    per_joint = [rd.score(detections, clean, joint=j) for j in range(scale.size)]
    minutes = per_joint[0].minutes
    return np.array([s.false_alarms / minutes for s in per_joint]), minutes


def operating_scale(cases: Sequence[tuple[Assayed, JointRecording]], goal: float
                    ) -> tuple[FloatArray, FloatArray, float]:  # fmt: skip
    """Per joint, the smallest factor on the threshold profile (to 0.2 %) at which the runs
    give at most ``goal`` false alarms per minute; the rate there, and the minutes."""
    residuals = [det.residual(rec) for det, rec in cases]
    ratios = []
    for (det, rec), r in zip(cases, residuals, strict=True):
        with np.errstate(divide="ignore", invalid="ignore"):
            ratios.append(np.nanmax(np.abs(r) / det.threshold(rec), axis=0))
    top = np.max(ratios, axis=0)  # above it nothing crosses: no onset at all
    if not np.all(np.isfinite(top) & (top > 0)):
        raise ConfigError("the detector's residual is zero or not finite on these runs")
    hi = top * 1.001
    lo = top * 1e-3
    for _ in range(SCALE_STEPS):
        mid = np.sqrt(lo * hi)
        rate, _ = _alarms(cases, residuals, mid)
        ok = rate <= goal
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid)
    rate, minutes = _alarms(cases, residuals, hi)
    return hi, rate, minutes


def _recall(cases: Sequence[tuple[Assayed, JointRecording]], scale: FloatArray,
            amplitude: FloatArray, units: Sequence[Sequence[FloatArray]]
            ) -> list[rd.Score]:  # fmt: skip
    """Per joint, the detectors' score with the unit pulses ``units`` (per case, per
    placement: pulse_labels, made once for every amplitude) at ``amplitude``."""
    marked = []  # the runs with the pulses' places as labels of 1 (whatever the amplitude,
    pushed = []  # which may be below the score's pulse level) and the detector on each
    for (det, rec), placed in zip(cases, units, strict=True):
        for unit in placed:
            run = with_pulses(rec, unit * amplitude)
            marked.append(replace(run, label=np.abs(unit)))
            pushed.append((det, run))
    detections = _detections(pushed, scale)
    return [rd.score(detections, marked, joint=j) for j in range(scale.size)]


def assay(
    cases: Sequence[tuple[Assayed, JointRecording]],
    settings: AssaySettings,
    limit_nm: FloatArray,
    progress: Callable[[str], None] | None = None,
) -> list[JointSensitivity]:
    """Per joint of ``cases`` (each a held-out run with the detector calibrated without it),
    its minimum detectable torque at the detector's own profile, scaled to the false-alarm
    goal. ``limit_nm``: per joint, the largest amplitude worth trying (its effort limit)."""
    if not cases:
        raise ConfigError("the assay needs at least one run without contact")
    joints = cases[0][1].joints
    scale, rate, minutes = operating_scale(cases, settings.alarms_per_minute)
    if progress:
        progress(
            "operating point: threshold x "
            + ", ".join(f"{j} {s:.3g}" for j, s in zip(joints, scale, strict=True))
            + f" ({minutes:.2f} min of runs)"
        )
    # the largest amplitude worth trying: well above the threshold, within the effort limit
    profiles = np.concatenate([det.threshold(rec) for det, rec in cases])
    judged = np.where(np.isfinite(profiles), profiles, np.nan)
    profile_top, profile_median = np.nanmax(judged, axis=0), np.nanmedian(judged, axis=0)
    hi = np.minimum(4.0 * scale * profile_top, limit_nm)
    lo = hi * 1e-2
    tried: list[list[tuple[float, float]]] = [[] for _ in joints]
    units = [[pulse_labels(rec, settings, p) for p in range(settings.placements)]
             for _, rec in cases]  # fmt: skip
    top_scores = _recall(cases, scale, hi, units)
    for j, s in enumerate(top_scores):
        tried[j].append((float(hi[j]), s.recall))
    reached = np.array([s.recall >= settings.recall for s in top_scores])
    best = list(top_scores)
    for step in range(AMPLITUDE_STEPS):
        mid = np.sqrt(lo * hi)
        scores = _recall(cases, scale, mid, units)
        for j, s in enumerate(scores):
            tried[j].append((float(mid[j]), s.recall))
            if s.recall >= settings.recall:  # (also where the largest tried fell short)
                hi[j] = mid[j]
                best[j] = s
                reached[j] = True
            else:
                lo[j] = mid[j]
        if progress:
            now = ", ".join(f"{j} {a:.3g} N m" for j, a in zip(joints, hi, strict=True))
            progress(f"bisection {step + 1}/{AMPLITUDE_STEPS}: {now}")
    out = []
    for j, joint in enumerate(joints):
        s = best[j]
        out.append(JointSensitivity(
            joint=joint, threshold_scale=float(scale[j]),
            threshold_nm=float(scale[j] * profile_median[j]), alarms_per_minute=float(rate[j]),
            minutes=minutes, min_torque_nm=float(hi[j]) if reached[j] else None,
            recall=s.recall, pulses=s.pulses,
            delay_median_s=s.delay_s(50) if reached[j] else math.nan,
            largest_tried_nm=float(tried[j][0][0]), tried=sorted(tried[j]),
        ))  # fmt: skip
    return out


def calibrated_detector(base: RobotModel, calibration: Calibration) -> Assayed:
    """The estimator node's calibrated observer (its pipeline, its speed-banded thresholds)."""
    return Assayed(
        residual=lambda rec: run_pipeline(base, calibration, rec)[0],
        threshold=lambda rec: calibration.threshold(rec.velocity),
    )


def textbook_detector(base: RobotModel, gain_per_s: float, clean: Sequence[JointRecording]
                      ) -> Assayed:  # fmt: skip
    """The textbook observer (the URDF as it is), its thresholds just above its largest residual
    on ``clean`` (as ``detect --method textbook --clean`` sets them)."""
    level = rd.constant_thresholds([rd.textbook_residual(base, r, gain_per_s) for r in clean])
    return Assayed(
        residual=lambda rec: rd.textbook_residual(base, rec, gain_per_s),
        threshold=lambda rec: np.broadcast_to(level, rec.position.shape),
    )


def folds(runs: Sequence[JointRecording], count: int) -> list[tuple[list[int], list[int]]]:
    """``count`` folds by run: fold f holds out runs f, f + count, ... and trains on the rest."""
    if count < 2 or len(runs) < count:
        raise ConfigError(
            f"{len(runs)} run(s) for {count} folds: each fold holds out some runs and calibrates "
            "on the others (give at least as many runs as folds, and at least 2 folds)"
        )
    idx = range(len(runs))
    return [([i for i in idx if i % count != f], [i for i in idx if i % count == f])
            for f in range(count)]  # fmt: skip


def named_effects(base: RobotModel, runs: Sequence[JointRecording]) -> list[Any]:
    """What the discrepancy tool names on ``runs`` (its final model's (effect, parameters))."""
    from transparency_ros.analysis.discrepancy.discover import Discoverer  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.robot import RobotProblem  # noqa: PLC0415

    return list(Discoverer(RobotProblem(base, runs)).run().fitted)


def named_detector(
    base: RobotModel,
    fitted: Sequence[tuple[Any, FloatArray]],
    clean: Sequence[JointRecording],
    gain_per_s: float,
) -> Assayed:
    """The momentum observer on the model the discrepancy tool names: the URDF with the
    effects of its final model (``fitted``: (effect, parameters), as its report has them),
    each where its physics acts (:mod:`robot_shooting`: payloads and a link's drift in the
    links' inertial parameters, delays, gains and saturations on the command's path, friction,
    offsets and cogging as torques the joint feels). Thresholds per speed band from ``clean``
    (runs without contact) as a calibration's are made."""
    model = carrying(base, fitted)

    def residual(rec: JointRecording) -> FloatArray:
        t = np.asarray(rec.stamps_ns * 1e-9, dtype=np.float64)
        felt = felt_torque(base, fitted, rec.position, rec.velocity)
        torque = command_path(base, fitted, t, rec.torque) - felt
        return rd.observer_residual(model, rec, gain_per_s, torque)

    thresholds = banded_thresholds(
        [residual(r) for r in clean], [r.velocity for r in clean], SPEED_BANDS, MARGIN
    )
    return Assayed(residual, lambda rec: at_speed(thresholds, SPEED_BANDS, rec.velocity))
