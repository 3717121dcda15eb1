"""What the discovery loop needs from a kind of recording (:class:`Problem`), and what every kind
shares: the split into fitting and held-out trials, a plot's :class:`Trace`, the position noise
behind the noise floor and the residual's dominant frequency."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.model import FloatArray, Trial

SIGNIFICANT = 1.5  # a held-out error within 1.5x the noise floor has nothing left to explain


class Problem(Protocol):
    """What the loop needs from a kind of recording (torque-driven windows, drop tests)."""

    nominal: dict[str, float]
    split: dict[str, list[str]]
    min_improvement: float  # share of the error above the noise floor an effect must remove

    def candidates(self) -> list[Any]: ...

    def initial(self, effect: Any) -> FloatArray: ...

    def error(self, effects: Sequence[Any], params: Sequence[FloatArray], held: bool) -> FloatArray:
        """Simulation error [rad] of every compared sample, 1-D, fitting or held-out trials."""
        ...

    def error_sets(
        self, effects: Sequence[Any], param_sets: Sequence[Sequence[FloatArray]], held: bool
    ) -> list[FloatArray]:
        """:meth:`error` for each set of parameters of ``effects`` (one batched simulation
        where the problem can: a fit's grid or Jacobian)."""
        ...

    def phases(self) -> dict[str, npt.NDArray[np.bool_]]:
        """Motion phase of every held-out error element."""
        ...

    def segments(self) -> tuple[npt.NDArray[np.int64], list[tuple[str, float, float]]]:
        """Segment index of every held-out error element; per segment (trial, t0, t1)."""
        ...

    def noise_floor(self) -> float: ...

    def residual_peak_hz(self, effects: Sequence[Any], params: Sequence[FloatArray]) -> float: ...

    def trace(
        self, effects: Sequence[Any], params: Sequence[FloatArray], segment: int
    ) -> Trace: ...


@dataclass(frozen=True)
class Trace:
    """One held-out segment, recorded against nominal and final model, for a plot."""

    title: str
    t: FloatArray
    recorded: FloatArray
    nominal: FloatArray
    final: FloatArray
    ylabel: str


def split_trials(
    trials: Sequence[Trial], heldout_fraction: float = 0.3
) -> tuple[list[Trial], list[Trial]]:
    """Every third-ish trial is held out (deterministic); one trial: its second half is held out."""
    if len(trials) == 1:
        tr = trials[0]
        half = tr.t.size // 2
        first = Trial(
            f"{tr.name}[first half]", tr.t[:half], tr.q[:half], tr.qd[:half], tr.tau[:half]
        )
        second = Trial(
            f"{tr.name}[second half]", tr.t[half:], tr.q[half:], tr.qd[half:], tr.tau[half:]
        )
        return [first], [second]
    every = max(2, round(1 / heldout_fraction))
    held = [tr for i, tr in enumerate(trials) if i % every == every - 1]
    fit = [tr for i, tr in enumerate(trials) if i % every != every - 1]
    if not held:  # two trials: the second is held out
        fit, held = list(trials[:-1]), [trials[-1]]
    return fit, held


def position_noise(q: FloatArray) -> float:
    """Standard deviation of white position noise (from second differences) and quantization
    (the smallest step), rows of ``q`` being separate recordings."""
    diffs = np.abs(np.diff(q, axis=-1))
    step = float(np.min(diffs[diffs > 0])) if np.any(diffs > 0) else 0.0
    white = float(np.median(np.abs(np.diff(q, n=2, axis=-1)))) / 0.6745 / math.sqrt(6)
    return math.hypot(white, step / math.sqrt(12))


def spectrum_peak(signal: FloatArray, fs: float, above_hz: float = 0.5) -> tuple[float, float]:
    """(frequency, power) of the largest Welch peak of ``signal`` above ``above_hz``."""
    from scipy.signal import welch  # noqa: PLC0415

    if signal.size < 8:
        return math.nan, -1.0
    f, power = welch(signal - signal.mean(), fs=fs, nperseg=min(signal.size, round(4 * fs)))
    keep = f > above_hz
    if not keep.any():
        return math.nan, -1.0
    i = int(np.argmax(power[keep]))
    return float(f[keep][i]), float(power[keep][i])
