"""Position-error estimate (eq. 1) vs generalized-momentum observer, on the same data.

Data (simulated with the one physics, so the true contact times are known): an actuator with the
drop-test arm follows theta_d(t) = A sin(2 pi f t) under the impedance controller (k_s = 2 N m/rad)
while external torque pulses (half-sine, random amplitude) hit the arm at known times. The
driver's view is what both estimators get: the encoder position (quantised) at 1 kHz, the
velocity as its finite difference (what firmware reports), and the drive torque.

Thresholds are set the same way for both: the largest |signal| over a quiet recording (motion,
no contact) plus a margin of 0.02 N m torque-equivalent (the paper's k_s epsilon). Reported per
estimator: detection delay (first onset after the pulse start), misses (no onset within the
pulse) and false alarms (onsets outside every pulse).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from transparency_ros.core.actuator_physics import (
    ActuatorPhysics,
    ImpedanceLaw,
    InertialLoad,
    PhysicsParams,
)
from transparency_ros.core.config import get_actuator, load_drop_test
from transparency_ros.core.estimator import DetectorSettings, SchmittDetector
from transparency_ros.core.momentum_observer import FrictionModel, MomentumObserver

K_S = 2.0
MARGIN_NM = 0.02


@dataclass(frozen=True)
class Recording:
    t_s: np.ndarray
    theta_d: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    drive_torque: np.ndarray
    pulses: list[tuple[float, float]]  # (start, end) of each external torque pulse


@dataclass(frozen=True)
class EstimatorScore:
    name: str
    threshold: float
    unit: str
    delays_s: list[float]
    misses: int
    false_alarms: int

    @property
    def median_delay_s(self) -> float:
        return float(np.median(self.delays_s)) if self.delays_s else math.nan

    @property
    def p90_delay_s(self) -> float:
        return float(np.percentile(self.delays_s, 90)) if self.delays_s else math.nan


def record(actuator_name: str, seconds: float, pulses: list[tuple[float, float, float]],
           amplitude_rad: float = 0.3, frequency_hz: float = 0.5) -> Recording:  # fmt: skip
    """Simulate; ``pulses`` are (start, duration, peak torque)."""
    actuator = get_actuator(actuator_name)
    arm = load_drop_test().arm_inertia_kgm2

    def external(_p: float, _v: float, t: float) -> float:
        for start, duration, peak in pulses:
            if start <= t < start + duration:
                return -peak * math.sin(math.pi * (t - start) / duration)
        return 0.0

    physics = ActuatorPhysics(PhysicsParams.from_actuator(actuator), InertialLoad(arm, external))
    dt = 0.001
    n = round(seconds / dt)
    t = np.arange(1, n + 1) * dt
    theta_d = amplitude_rad * np.sin(2 * math.pi * frequency_hz * t)
    velocity_d = amplitude_rad * 2 * math.pi * frequency_hz * np.cos(2 * math.pi * frequency_hz * t)
    position = np.empty(n)
    torque = np.empty(n)
    for i in range(n):
        physics.advance(dt, ImpedanceLaw(K_S, 0.0, float(theta_d[i]), float(velocity_d[i]), 0.0))
        position[i] = physics.measured_position_rad
        torque[i] = physics.state.applied_torque_nm
    velocity = np.diff(position, prepend=position[0]) / dt
    return Recording(t, theta_d, position, velocity, torque, [(s, s + d) for s, d, _ in pulses])


def _signals(rec: Recording, actuator_name: str, gain_per_s: float) -> dict[str, np.ndarray]:
    model = FrictionModel.from_actuator(
        get_actuator(actuator_name), load_drop_test().arm_inertia_kgm2
    )
    observer = MomentumObserver(model, gain_per_s)
    residual = np.array(
        [
            observer.update(float(t), float(v), float(tau))
            for t, v, tau in zip(rec.t_s, rec.velocity, rec.drive_torque, strict=True)
        ]
    )
    return {
        "position error (eq. 1)": rec.theta_d - rec.position,
        f"momentum observer (K_o = {gain_per_s:g}/s)": residual,
    }


def _score(name: str, unit: str, signal: np.ndarray, threshold: float,
           rec: Recording) -> EstimatorScore:  # fmt: skip
    detector = SchmittDetector(
        DetectorSettings(contact_onset=threshold, contact_release=threshold / 2)
    )
    onsets = [
        ev.stamp_ns * 1e-9
        for t, value in zip(rec.t_s, signal, strict=True)
        for ev in detector.update("j", round(t * 1e9), float(value), 0.0)
        if ev.kind.value == "contact_onset"
    ]
    delays: list[float] = []
    misses = 0
    for start, end in rec.pulses:
        hits = [s for s in onsets if start <= s <= end]
        if hits:
            delays.append(hits[0] - start)
        else:
            misses += 1
    false_alarms = sum(1 for s in onsets if not any(a <= s <= b for a, b in rec.pulses))
    return EstimatorScore(name, threshold, unit, delays, misses, false_alarms)


def compare(actuator_name: str = "EC60", gain_per_s: float = 100.0, seed: int = 7,
            pulses: int = 40, amplitude_rad: float = 0.3) -> list[EstimatorScore]:  # fmt: skip
    """Quiet recording for thresholds, then a recording with contacts; both estimators.

    ``amplitude_rad`` = 0 holds still (the drop-test situation); > 0 tracks a 0.5 Hz sine.
    """
    rng = np.random.default_rng(seed)
    quiet = record(actuator_name, 10.0, [], amplitude_rad)
    schedule = [
        (1.0 + 0.5 * i + rng.uniform(0, 0.2), 0.03, float(rng.uniform(0.1, 0.6)))
        for i in range(pulses)
    ]
    trial = record(actuator_name, 1.0 + 0.5 * pulses + 0.5, schedule, amplitude_rad)
    quiet_signals = _signals(quiet, actuator_name, gain_per_s)
    trial_signals = _signals(trial, actuator_name, gain_per_s)
    scores = []
    for (name, q), signal in zip(quiet_signals.items(), trial_signals.values(), strict=True):
        is_position = name.startswith("position")
        margin = MARGIN_NM / K_S if is_position else MARGIN_NM
        threshold = float(np.max(np.abs(q))) + margin
        scores.append(_score(name, "rad" if is_position else "N m", signal, threshold, trial))
    return scores
