"""The 1-DoF torque-driven model the discrepancy tool simulates, with pluggable effects.

Nominal dynamics (output side), with the terms of a YAML spec:

    J q'' = tau_in - b q' - tau_c sign(q') - m g l sin(q + q_0)   (stick-slip at q' = 0)

An effect (:mod:`.effects`) may add a torque, transform the input torque (saturation, delay),
transform what the sensor reports (delay, quantization) or hold the joint (stiction). Simulation
is *windowed* (multiple shooting): every window of ``window_s`` starts from the recorded state and
is integrated open loop on the recorded input, all windows of all trials at once in numpy. The
simulation error of a window says how well the model predicts the next ``window_s`` seconds; a
long single rollout of a swinging pendulum diverges and says little.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from transparency_ros.core.config import finite_number
from transparency_ros.core.errors import ConfigError, ModelError

FloatArray = npt.NDArray[np.float64]
GRAVITY = 9.81
MARGIN_S = 0.06  # input kept from before each window (longest delay the tool tries)
NOMINAL_TERMS = (
    "inertia_kgm2",
    "viscous_nms_per_rad",
    "coulomb_nm",
    "gravity_nm",
    "gravity_offset_rad",
)


@dataclass(frozen=True)
class NominalModel:
    inertia_kgm2: float
    viscous_nms_per_rad: float = 0.0
    coulomb_nm: float = 0.0
    gravity_nm: float = 0.0  # m g l of the payload the nominal model knows
    gravity_offset_rad: float = 0.0
    coulomb_smoothing_rad_s: float = 0.05  # v_c of the tanh

    def __post_init__(self) -> None:
        if not (math.isfinite(self.inertia_kgm2) and self.inertia_kgm2 > 0):
            raise ModelError(f"inertia_kgm2 must be > 0, got {self.inertia_kgm2!r}")

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in NOMINAL_TERMS}


def read_spec(path: Path) -> Mapping[str, Any]:
    """The mapping of terms in a nominal-model YAML file."""
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f"{path}: cannot read the nominal model: {err}") from err
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path}: a nominal model is a mapping of terms")
    return data


def load_nominal(path: str | Path) -> NominalModel:
    """A nominal model from a YAML spec: ``{inertia_kgm2: .., viscous_nms_per_rad: .., ...}``,
    or the parameter file format of the DFKI simple pendulum (mass, length, inertia, damping,
    coulomb_fric, gravity)."""
    p = Path(path)
    data = read_spec(p)
    if "mass" in data and "length" in data:  # DFKI pendulum parameters
        m = finite_number(data["mass"], f"{p}: mass")
        length = finite_number(data["length"], f"{p}: length")
        g = finite_number(data.get("gravity", GRAVITY), f"{p}: gravity")
        given = data.get("inertia")  # 'None' in some files: a point mass at the length
        inertia = (
            m * length**2 if given in (None, "None") else finite_number(given, f"{p}: inertia")
        )
        return NominalModel(
            inertia_kgm2=inertia,
            viscous_nms_per_rad=finite_number(data.get("damping", 0.0), f"{p}: damping"),
            coulomb_nm=finite_number(data.get("coulomb_fric", 0.0), f"{p}: coulomb_fric"),
            gravity_nm=m * g * length,
        )
    unknown = sorted(set(data) - set(NOMINAL_TERMS))
    if unknown:
        raise ConfigError(f"{p}: unknown nominal terms {unknown}; known: {list(NOMINAL_TERMS)}")
    if "inertia_kgm2" not in data:
        raise ConfigError(f"{p}: inertia_kgm2 is required")
    return NominalModel(**{k: finite_number(v, f"{p}: {k}") for k, v in data.items()})


@dataclass(frozen=True)
class Trial:
    """One recording: time [s], position [rad], velocity [rad/s], input torque [N m]."""

    name: str
    t: FloatArray
    q: FloatArray
    qd: FloatArray
    tau: FloatArray

    def __post_init__(self) -> None:
        n = self.t.size
        if n < 10 or any(a.shape != (n,) for a in (self.q, self.qd, self.tau)):
            raise ModelError(f"trial {self.name}: need >= 10 samples of t, q, qd, tau alike")
        if not np.all(np.diff(self.t) > 0):
            raise ModelError(f"trial {self.name}: time must increase")
        if not all(np.isfinite(a).all() for a in (self.t, self.q, self.qd, self.tau)):
            raise ModelError(f"trial {self.name}: NaN or inf in the data")

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.t)))


@dataclass
class Windows:
    """All windows of a set of trials as (n_windows, steps) arrays."""

    trial_index: npt.NDArray[np.int64]  # (w,)
    start_index: npt.NDArray[np.int64]  # (w,) sample index in its trial
    t: FloatArray  # (w, s) time of each step
    q: FloatArray  # recorded position
    qd: FloatArray  # recorded velocity
    tau: FloatArray  # recorded input torque
    dt: float
    extra: dict[str, Any] = field(default_factory=dict)


def make_windows(
    trials: Sequence[Trial], window_s: float, stride_s: float | None = None
) -> Windows:
    """Cut every trial into windows of ``window_s`` (stride defaults to the window length)."""
    if not trials:
        raise ModelError("no trials")
    dt = float(np.median([tr.dt for tr in trials]))
    steps = max(3, round(window_s / dt))
    stride = max(1, round((stride_s or window_s) / dt))
    rows: list[tuple[int, int]] = []
    for i, tr in enumerate(trials):
        for start in range(0, tr.t.size - steps, stride):
            rows.append((i, start))
    if not rows:
        raise ModelError(f"trials shorter than one window of {window_s} s")
    ti = np.array([r[0] for r in rows], dtype=np.int64)
    si = np.array([r[1] for r in rows], dtype=np.int64)

    def cut(attr: str) -> FloatArray:
        return np.stack([getattr(trials[i], attr)[s : s + steps] for i, s in rows])

    # initial velocities from a smoothing derivative of the position (the recorded velocity is
    # often a finite difference of a quantized encoder: too noisy to start a rollout from)
    smooth = [_smooth_velocity(tr) for tr in trials]
    w = Windows(ti, si, cut("t"), cut("q"), cut("qd"), cut("tau"), dt)
    w.extra["qd0"] = np.array([smooth[i][s] for i, s in rows])
    # the input before each window (delays reach back into it), edge-padded at a trial's start
    margin = max(1, round(MARGIN_S / dt))
    w.extra["tau_before"] = np.stack(
        [
            np.pad(trials[i].tau[max(0, s - margin) : s], (margin - min(margin, s), 0), mode="edge")
            if s > 0
            else np.full(margin, trials[i].tau[0])
            for i, s in rows
        ]
    )
    return w


def smooth_derivatives(
    trial: Trial, span_s: float, polyorder: int
) -> tuple[FloatArray, FloatArray]:
    """q' and q'' from a Savitzky-Golay fit of the position over ``span_s`` (the one place the
    tool differentiates recorded positions; the recorded velocity is often too noisy)."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    n = max(5, round(span_s / trial.dt) | 1)
    if n >= trial.t.size:
        return trial.qd, np.gradient(trial.qd, trial.t)
    qd = savgol_filter(trial.q, n, polyorder, deriv=1, delta=trial.dt)
    qdd = savgol_filter(trial.q, n, polyorder, deriv=2, delta=trial.dt)
    return np.asarray(qd, dtype=float), np.asarray(qdd, dtype=float)


def _smooth_velocity(trial: Trial, span_s: float = 0.01) -> FloatArray:
    return smooth_derivatives(trial, span_s, 2)[0]


def simulate(
    model: NominalModel, effects: Sequence[Any], params: Sequence[FloatArray], w: Windows
) -> FloatArray:
    """Predicted measured position for every window step, (n_windows, steps), integrated over
    the recorded sample times (real recordings jitter and drop samples: the real double
    pendulum's 2.5 ms steps reach 7.6 ms; a fixed step would integrate a gap as one step)."""
    n, steps = w.q.shape
    h = np.diff(w.t, axis=1)
    for effect, p in zip(effects, params, strict=True):
        model = effect.adjust(model, p)
    tau = w.tau
    for effect, p in zip(effects, params, strict=True):
        tau = effect.input(tau, p, w)
    q = w.q[:, 0].copy()
    qd = np.array(w.extra.get("qd0", w.qd[:, 0]), dtype=float)
    out = np.empty((n, steps))
    out[:, 0] = q
    inv_j = 1.0 / model.inertia_kgm2
    for k in range(1, steps):
        drive = tau[:, k - 1]
        extra = np.zeros(n)
        for effect, p in zip(effects, params, strict=True):
            extra = extra + effect.torque(q, qd, p)
        # every torque but friction: what friction has to hold at rest
        active = drive + extra - model.gravity_nm * np.sin(q + model.gravity_offset_rad)
        # Coulomb friction with stick-slip (Karnopp), as the project's actuator physics has it:
        # opposing the motion, or at rest the torque trying to start it
        direction = np.where(qd != 0.0, np.sign(qd), np.sign(active))
        net = active - model.viscous_nms_per_rad * qd - model.coulomb_nm * direction
        dt = h[:, k - 1]
        qd_new = qd + net * inv_j * dt
        through_zero = (qd == 0.0) | (qd * qd_new < 0.0)
        qd_new = np.where(through_zero & (np.abs(active) <= model.coulomb_nm), 0.0, qd_new)
        for effect, p in zip(effects, params, strict=True):
            qd_new = effect.hold(qd, qd_new, active, p, model)
        qd = qd_new
        q = q + qd * dt
        out[:, k] = q
    for effect, p in zip(effects, params, strict=True):
        out = effect.measure(out, p, w)
    return out


def with_params(model: NominalModel, **changes: float) -> NominalModel:
    return replace(model, **changes)
