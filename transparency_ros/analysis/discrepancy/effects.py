"""Candidate effects: physics a nominal model may have left out, each with named SI parameters.

An effect acts where its physics acts: an added torque (torque_offset, cogging, payload_gravity),
the input path (torque_saturation), the joint's motion (stiction holds it), the sensor
(sensor_delay, quantization), or the nominal terms themselves (parameter_drift: a nominal value
is wrong; it names the term and gives the refitted value). ``initial`` guesses parameters from
the inverse-dynamics residual of the recorded data, so fits start near the answer.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.model import (
    FloatArray,
    NominalModel,
    Trial,
    Windows,
    smooth_derivatives,
)

STUCK_SPEED_RAD_S = 0.02


def inverse_dynamics_residual(
    model: NominalModel, trials: Sequence[Trial]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(q, qd, torque the nominal model misses) over all samples: J q'' + passive - tau."""
    qs, qds, res = [], [], []
    for tr in trials:
        qd, qdd = smooth_derivatives(tr, 0.02, 3)
        passive = (
            model.viscous_nms_per_rad * qd
            + model.coulomb_nm * np.tanh(qd / model.coulomb_smoothing_rad_s)
            + model.gravity_nm * np.sin(tr.q + model.gravity_offset_rad)
        )
        qs.append(tr.q)
        qds.append(qd)
        res.append(model.inertia_kgm2 * qdd + passive - tr.tau)
    return np.concatenate(qs), np.concatenate(qds), np.concatenate(res)


@dataclass
class Effect:
    name: str
    param_names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        return np.array([(lo + hi) / 2 for lo, hi in zip(self.lower, self.upper, strict=True)])

    def adjust(self, model: NominalModel, p: FloatArray) -> NominalModel:
        return model

    def input(self, tau: FloatArray, p: FloatArray, w: Windows) -> FloatArray:
        return tau

    def torque(self, q: FloatArray, qd: FloatArray, p: FloatArray) -> FloatArray | float:
        return 0.0

    def hold(
        self,
        qd_old: FloatArray,
        qd_new: FloatArray,
        drive: FloatArray,
        p: FloatArray,
        model: NominalModel,
    ) -> FloatArray:
        return qd_new

    def measure(self, out: FloatArray, p: FloatArray, w: Windows) -> FloatArray:
        return out

    @property
    def fittable(self) -> bool:
        return True

    discrete_choices = 0  # choices made from the data besides the fitted parameters

    def meaningful(self, p: FloatArray) -> bool:
        """Whether fitted values name something (drift scales near 1 name nothing)."""
        return True

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        """Values reported with the fitted parameters (cogging's period)."""
        return {}


class TorqueOffset(Effect):
    def __init__(self) -> None:
        super().__init__("torque_offset", ("offset_nm",), (-5.0,), (5.0,))

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        _, _, r = inverse_dynamics_residual(model, trials)  # r = the torque the model misses
        return np.array([float(np.clip(np.median(r), -5.0, 5.0))])

    def torque(self, q: FloatArray, qd: FloatArray, p: FloatArray) -> float:
        return float(p[0])

    def meaningful(self, p: FloatArray) -> bool:
        # held at +-5 N m it stands in (the range is symmetric: its size as a magnitude)
        return not pinned(np.abs(p), self.lower, self.upper)


def strongest_wave(
    waves: Callable[[int], FloatArray], residual: FloatArray
) -> tuple[int, float, float]:
    """(N, amplitude, phase) of the wave a sin + b cos of N q (``waves(N)``: its two columns
    alike ``residual``'s samples) that explains most of ``residual``, N from 2 to 60 (N = 1
    is a payload's gravity, not cogging). Shared by the 1-DoF and the robot cogging."""
    best = (0.0, 2, 0.0, 0.0)
    for n in range(2, 61):
        basis = waves(n)
        (a, b), *_ = np.linalg.lstsq(basis, residual, rcond=None)
        explained = float(np.sum((basis @ np.array([a, b])) ** 2))
        if explained > best[0]:
            best = (explained, n, math.hypot(a, b), math.atan2(b, a))
    return best[1], best[2], best[3]


class Cogging(Effect):
    """tau = A sin(N q + phi), N (cycles per output revolution) picked from the residual."""

    def __init__(self, cycles_per_rev: int = 0) -> None:
        super().__init__("cogging", ("amplitude_nm", "phase_rad"), (0.0, -math.pi), (5.0, math.pi))
        self.cycles_per_rev = cycles_per_rev

    cycles_per_rev: int
    discrete_choices = 1

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        return {"cycles_per_rev": float(self.cycles_per_rev)}

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        q, _, r = inverse_dynamics_residual(model, trials)
        n, amplitude, phase = strongest_wave(lambda k: np.c_[np.sin(k * q), np.cos(k * q)], r)
        self.cycles_per_rev = n  # the period is chosen here, from the data
        return np.array([min(amplitude, 5.0), phase])

    def torque(self, q: FloatArray, qd: FloatArray, p: FloatArray) -> FloatArray:
        return np.asarray(p[0] * np.sin(self.cycles_per_rev * q + p[1]), dtype=float)


class PayloadGravity(Effect):
    def __init__(self) -> None:
        super().__init__(
            "payload_gravity", ("mgl_nm", "offset_rad"), (0.0, -2 * math.pi), (20.0, 2 * math.pi)
        )

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        q, _, r = inverse_dynamics_residual(model, trials)
        # r ~ mgl sin(q + o) = mgl cos(o) sin q + mgl sin(o) cos q
        a, b = np.linalg.lstsq(np.c_[np.sin(q), np.cos(q)], r, rcond=None)[0]
        # r = -mgl sin(q + o) = -mgl cos(o) sin q - mgl sin(o) cos q
        return np.array([float(min(math.hypot(a, b), 20.0)), math.atan2(-b, -a)])

    def torque(self, q: FloatArray, qd: FloatArray, p: FloatArray) -> FloatArray:
        return np.asarray(-p[0] * np.sin(q + p[1]), dtype=float)


class Stiction(Effect):
    """Below a small speed the joint sticks until the driving torque exceeds static_nm."""

    def __init__(self) -> None:
        super().__init__("stiction", ("static_nm",), (0.0,), (3.0,))

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        return np.array([max(model.coulomb_nm * 2.0, 0.05)])

    def hold(
        self,
        qd_old: FloatArray,
        qd_new: FloatArray,
        drive: FloatArray,
        p: FloatArray,
        model: NominalModel,
    ) -> FloatArray:
        through_zero = (qd_old == 0.0) | (qd_old * qd_new <= 0.0)
        stuck = through_zero & (np.abs(drive) <= p[0])
        return np.where(stuck, 0.0, qd_new)


class TorqueSaturation(Effect):
    def __init__(self) -> None:
        super().__init__("torque_saturation", ("limit_nm",), (0.01,), (50.0,))

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        peak = max(float(np.max(np.abs(tr.tau))) for tr in trials)
        return np.array([0.8 * peak])

    def input(self, tau: FloatArray, p: FloatArray, w: Windows) -> FloatArray:
        return np.clip(tau, -p[0], p[0])

    def meaningful(self, p: FloatArray) -> bool:
        # a limit held at its lowest value removes the recorded torque altogether: on a
        # recording whose torque explains little of the motion that fits best, and it names
        # no saturation (an offset of 3.9 N m on the real AK80-6 run was named so)
        return not pinned(p, self.lower, self.upper)


class SensorDelay(Effect):
    """Position and torque are ``delay_s`` apart (a late encoder or a late current loop): the
    recorded motion answers the torque recorded ``delay_s`` earlier."""

    def __init__(self) -> None:
        super().__init__("sensor_delay", ("delay_s",), (0.0,), (0.05,))

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        return np.array([0.005])

    def input(self, tau: FloatArray, p: FloatArray, w: Windows) -> FloatArray:
        before = w.extra["tau_before"]
        full = np.concatenate([before, tau], axis=1)
        m = before.shape[1]
        k = np.arange(tau.shape[1], dtype=float) + m - p[0] / w.dt
        k0 = np.clip(np.floor(k).astype(int), 0, full.shape[1] - 1)
        k1 = np.clip(k0 + 1, 0, full.shape[1] - 1)
        frac = np.clip(k - np.floor(k), 0.0, 1.0)
        return np.asarray(full[:, k0] * (1 - frac) + full[:, k1] * frac, dtype=float)

    def meaningful(self, p: FloatArray) -> bool:
        # 0 is no delay, plausible; the longest the tool tries stands in for something else
        return not pinned(p, self.lower, self.upper)


class Quantization(Effect):
    """The position is reported on a lattice of ``step_rad`` (encoder resolution)."""

    def __init__(self) -> None:
        super().__init__("quantization", ("step_rad",), (1e-7,), (0.1,))

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        steps = np.concatenate([np.abs(np.diff(tr.q)) for tr in trials])
        nonzero = steps[steps > 1e-12]
        return np.array([float(np.min(nonzero)) if nonzero.size else 1e-6])

    def measure(self, out: FloatArray, p: FloatArray, w: Windows) -> FloatArray:
        return np.asarray(np.round(out / p[0]) * p[0], dtype=float)

    @property
    def fittable(self) -> bool:
        return False  # the lattice is read off the data; a gradient fit cannot move it


class ParameterDrift(Effect):
    """A nominal value is wrong: scale factors of inertia, viscous, Coulomb and gravity terms."""

    TERMS = ("inertia_kgm2", "viscous_nms_per_rad", "coulomb_nm", "gravity_nm")

    def __init__(self) -> None:
        super().__init__(
            "parameter_drift",
            ("inertia_scale", "viscous_scale", "coulomb_scale", "gravity_scale"),
            (0.2, 0.0, 0.0, 0.2),
            (5.0, 5.0, 5.0, 5.0),
        )

    def initial(self, model: NominalModel, trials: Sequence[Trial]) -> FloatArray:
        return np.ones(4)

    def meaningful(self, p: FloatArray) -> bool:
        return drifted(p) and not pinned(p, self.lower, self.upper)

    def adjust(self, model: NominalModel, p: FloatArray) -> NominalModel:
        return replace(
            model, **{t: getattr(model, t) * float(s) for t, s in zip(self.TERMS, p, strict=True)}
        )


DRIFT_MIN = 0.2  # a nominal value counts as wrong when off by more than 20 %
BOUND_SHARE = 0.01  # a fit this share of its range from a bound is held there (pinned)


def drifted_terms(scales: FloatArray) -> npt.NDArray[np.bool_]:
    """Which scales are off nominal by more than ``DRIFT_MIN``."""
    return np.abs(np.asarray(scales, dtype=float) - 1.0) > DRIFT_MIN


def drifted(scales: FloatArray) -> bool:
    return bool(np.any(drifted_terms(scales)))


def pinned(p: FloatArray, lower: Sequence[float], upper: Sequence[float]) -> bool:
    """A fit held at a bound of its plausible range (a scale of 5, an inertia cut to a fifth):
    the drift then stands in for something it cannot be. A scale of 0 (a term that is not
    there) is plausible."""
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    x, near = np.asarray(p, dtype=float), BOUND_SHARE * (hi - lo)
    return bool(np.any(x >= hi - near) or np.any((lo > 0) & (x <= lo + near)))


def library() -> list[Effect]:
    """The candidates the tool tries, in a fixed order."""
    return [
        ParameterDrift(),
        TorqueOffset(),
        PayloadGravity(),
        Stiction(),
        Cogging(),
        TorqueSaturation(),
        SensorDelay(),
        Quantization(),
    ]


NOT_YET = ("backlash", "restitution", "impact_speed_loss", "structural_compliance")
