"""What the discovery loop needs from a kind of recording (:class:`Problem`), and what every kind
shares: the split into fitting and held-out trials, a plot's :class:`Trace`, the position noise
behind the noise floor and the residual's dominant frequency."""

from __future__ import annotations

import inspect
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


class Hooks:
    """What a :class:`Problem` may say besides what it must, with what the loop assumes where
    it says nothing: the values and methods here, bound to the problem. A kind of recording
    defines only the ones it changes (drop tests, their load cell's view, robots); the loop
    reads each through :func:`hook`, which refuses a name not declared here."""

    # notes on the data, said in every report
    notes: Sequence[str] = ()
    # the share of its value every named parameter's 95 % interval is widened by (the model's
    # own error, measured where the truth is known)
    model_error_share = 0.0
    # what the compared error is of, and its unit, as the findings say it
    channel = "simulation"
    unit = "rad"
    # the sensor whose error :meth:`leftover_scope` singles out, as the report names it
    scoped_sensor = "sensor"
    # effects the recording declares (nothing fitted) are named before any search
    declared_stage = True
    # two candidates are fitted together where none names alone
    pairs = True
    # a named effect's parameters are fitted again with those found before it
    joint_refit = True
    # the search goes on below SIGNIFICANT times the floor, and a step judged there must
    # take the error down to the floor
    to_the_floor = False
    # a method (held) -> the trial of every element of ``error``; None: not said
    trial_index = None

    def structure_left(self: Any, err: FloatArray) -> bool:
        """Whether the held-out error ``err`` has structure left to search for."""
        floor: float = self.noise_floor()
        return float(np.sqrt(np.mean(err**2))) > SIGNIFICANT * floor

    def force_view(self: Any) -> Any:
        """A second view of the recordings searched after the first (a drop test's load
        cell), or None."""
        return None

    def shows_elsewhere(self: Any, step: Any, base: Any) -> bool:
        """Whether a step that removes too little of the pooled error shows on another
        sensor enough to be judged there."""
        return False

    def accepts(self: Any, effects: Sequence[Any], params: Sequence[FloatArray]) -> bool:
        """Whether the problem allows this model whatever it explains."""
        return True

    def sensor_scope(
        self: Any, effects: Sequence[Any], after_search: bool = False, modelled: Sequence[Any] = ()
    ) -> tuple[npt.NDArray[np.bool_], float] | None:
        """(mask, floor) of the one sensor's error the effects added to the model
        (``modelled``: those found before) are judged on, or None: all of it."""
        return None

    def leftover_scope(self: Any, err: FloatArray) -> tuple[npt.NDArray[np.bool_], float] | None:
        """(mask, floor) of the one sensor whose error is left above its floor in ``err``
        where the pooled is near its own, or None."""
        return None

    def expected(self: Any, effect: Any, params: FloatArray) -> bool:
        """Whether a step's effect is what the recording leads one to expect (chosen first
        among steps alike)."""
        return False

    def told_apart(self: Any, named: Sequence[Any], other: Sequence[Any]) -> str:
        """Why effects alike in the held-out error cannot be told apart, where the recordings
        say ("": not said)."""
        return ""

    def state_explained(
        self: Any, effects: Sequence[Any], params: Sequence[FloatArray]
    ) -> float | None:
        """The share of the final model's residual a function of the state explains, for the
        unexplained residual's description (None: not said)."""
        return None


_ABSENT = object()


def hook(problem: Any, name: str) -> Any:
    """The problem's own ``name`` or, where it has none, :class:`Hooks`' (a method bound to
    the problem). A name Hooks does not declare is refused (a misspelt hook would otherwise
    fall silently to a default)."""
    default = Hooks.__dict__.get(name, _ABSENT)
    if default is _ABSENT:
        raise AttributeError(f"{name!r} is not an optional hook of a Problem (see Hooks)")
    own = getattr(problem, name, _ABSENT)
    if own is not _ABSENT:
        return own
    return default.__get__(problem) if inspect.isfunction(default) else default


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
