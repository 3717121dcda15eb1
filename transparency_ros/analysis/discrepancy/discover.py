"""The loop: simulate -> residual -> locate -> explain -> model -> select, until nothing is left.

The loop is the same for every kind of recording; a *problem* (:class:`Problem`) says how to
simulate its trials and compare them: :class:`TorqueDrivenProblem` for 1-DoF torque-driven
recordings, :class:`~transparency_ros.analysis.discrepancy.drop.DropProblem` for drop tests.

Trials are split into fitting and held-out sets (whole trials, never samples of one trial). Each
round fits every remaining candidate effect (its own parameters, bounded least squares on the
simulation error of the fitting trials; then all parameters found so far together with it),
scores it on the held-out trials, and keeps the best only if it removes at least
``min_improvement`` of the held-out error above the noise floor (what sensor noise alone would
cause), at least a tenth of the floor in absolute terms, the held-out information criterion
(n log(RSS/n) + 2k) improves by more than 10, and its fit is meaningful. When no single
candidate passes and structure is left, candidates are fitted two at a time (two missing
effects may each explain too little alone). A kept effect gets its parameters with 95 %
confidence intervals (from the fit's Jacobian), where it acted (the motion phase whose residual
it reduced most, and the trial and time window of the largest reduction) and the evidence. What
is left is checked for structure (phase RMS against the noise floor, its dominant frequency, how
much of it the state explains, the closest candidate) and reported as ``unexplained``, never
forced onto a label.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from transparency_ros.analysis.discrepancy.effects import (
    Effect,
    inverse_dynamics_residual,
    library,
)
from transparency_ros.analysis.discrepancy.model import (
    FloatArray,
    NominalModel,
    Trial,
    Windows,
    make_windows,
    simulate,
)
from transparency_ros.core.errors import ModelError

GRID_POINTS = 25
PAIR_FINALISTS = 3  # pairs refitted with the effects found before them
STATE_EXPLAINED = 0.3  # below: the leftover torque is not a function of the state
SIGNIFICANT = 1.5  # a held-out error within 1.5x the noise floor has nothing left to explain
LEFTOVER = 3.0  # a phase whose residual is above 3x the noise floor is left unexplained
PHASES = ("stuck", "reversal", "slow", "fast")


@dataclass(frozen=True)
class Finding:
    effect: str
    parameters: dict[str, float]
    confidence_interval: dict[str, tuple[float, float]]
    where: dict[str, Any]
    evidence: str
    heldout_rmse_before: float
    heldout_rmse_after: float
    alternatives: list[str] = field(default_factory=list)  # explain the data as well


@dataclass
class Report:
    nominal: dict[str, float]
    split: dict[str, list[str]]
    findings: list[Finding] = field(default_factory=list)
    unexplained: list[dict[str, Any]] = field(default_factory=list)
    heldout_rmse_nominal: float = math.nan
    final_heldout_rmse: float = math.nan
    seconds: float = 0.0
    fitted: list[tuple[Any, FloatArray]] = field(default_factory=list)  # effects as found

    def as_dict(self) -> dict[str, Any]:
        return {
            "findings": [vars(f) for f in self.findings],
            "unexplained": self.unexplained,
            "nominal": self.nominal,
            "split": self.split,
            "heldout_rmse_nominal": self.heldout_rmse_nominal,
            "final_heldout_rmse": self.final_heldout_rmse,
            "seconds": self.seconds,
        }


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
    return fit, held


def window_phases(w: Windows) -> dict[str, FloatArray]:
    speed = np.abs(w.qd)
    sign_change = np.zeros_like(speed, dtype=bool)
    sign_change[:, 1:] = np.sign(w.qd[:, 1:]) != np.sign(w.qd[:, :-1])
    near_rev = sign_change.copy()
    for shift in range(1, 6):  # a few samples around a reversal
        near_rev[:, :-shift] |= sign_change[:, shift:]
        near_rev[:, shift:] |= sign_change[:, :-shift]
    fast_level = np.percentile(speed, 60)
    stuck = speed < 0.02
    return {
        "stuck": stuck,
        "reversal": near_rev & ~stuck,
        "slow": ~stuck & ~near_rev & (speed < fast_level),
        "fast": ~stuck & ~near_rev & (speed >= fast_level),
    }


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


class TorqueDrivenProblem:
    """1-DoF torque-driven recordings, simulated in windows of ``window_s`` (multiple shooting)."""

    def __init__(
        self,
        model: NominalModel,
        trials: Sequence[Trial],
        *,
        window_s: float = 0.1,
        candidates: Sequence[Effect] | None = None,
    ) -> None:
        self.model = model
        self.fit_trials, self.held_trials = split_trials(trials)
        self.w_fit = make_windows(self.fit_trials, window_s, stride_s=window_s)
        self.w_held = make_windows(self.held_trials, window_s, stride_s=window_s)
        self._candidates = list(candidates) if candidates is not None else library()
        self.min_improvement = 0.5
        self.nominal = model.as_dict()
        self.split = {
            "fit": [t.name for t in self.fit_trials],
            "heldout": [t.name for t in self.held_trials],
        }

    def candidates(self) -> list[Effect]:
        return list(self._candidates)

    def initial(self, effect: Effect) -> FloatArray:
        return effect.initial(self.model, self.fit_trials)

    def error(
        self, effects: Sequence[Effect], params: Sequence[FloatArray], held: bool
    ) -> FloatArray:
        w = self.w_held if held else self.w_fit
        return (simulate(self.model, effects, params, w) - w.q).ravel()

    def error_sets(
        self, effects: Sequence[Effect], param_sets: Sequence[Sequence[FloatArray]], held: bool
    ) -> list[FloatArray]:
        return [self.error(effects, params, held) for params in param_sets]

    def phases(self) -> dict[str, npt.NDArray[np.bool_]]:
        return {
            name: np.asarray(mask, dtype=bool).ravel()
            for name, mask in window_phases(self.w_held).items()
        }

    def segments(self) -> tuple[npt.NDArray[np.int64], list[tuple[str, float, float]]]:
        w = self.w_held
        n, steps = w.q.shape
        labels = []
        for i in range(n):
            trial = self.held_trials[int(w.trial_index[i])]
            t0 = float(w.t[i, 0] - trial.t[0])
            labels.append((trial.name, t0, t0 + steps * w.dt))
        return np.repeat(np.arange(n, dtype=np.int64), steps), labels

    def noise_floor(self) -> float:
        """The window error noise alone causes: position noise (incl. quantization) plus the
        error of the smoothed initial velocity integrated over a window (a quadratic fit over
        n samples has slope variance 12 sigma^2 / (n (n^2 - 1) dt^2))."""
        w = self.w_fit
        q_noise = position_noise(w.q)
        n = max(5, round(0.01 / w.dt) | 1)
        v_noise = q_noise * math.sqrt(12 / (n * (n * n - 1))) / w.dt
        span = w.q.shape[1] * w.dt
        return math.hypot(q_noise, v_noise * span / math.sqrt(3))

    def residual_peak_hz(self, effects: Sequence[Effect], params: Sequence[FloatArray]) -> float:
        """Frequency [Hz] where the held-out torque residual (inverse dynamics with the found
        torque effects, over whole trials, Welch spectrum) has most power above 0.5 Hz."""
        model = self.model
        for effect, p in zip(effects, params, strict=True):
            model = effect.adjust(model, p)
        best_f, best_p = math.nan, -1.0
        for trial in self.held_trials:
            q, qd, r = inverse_dynamics_residual(model, [trial])
            for effect, p in zip(effects, params, strict=True):
                r = r - np.broadcast_to(effect.torque(q, qd, p), r.shape)
            f, power = spectrum_peak(r, 1.0 / trial.dt)
            if power > best_p:
                best_f, best_p = f, power
        return best_f

    def trace(self, effects: Sequence[Effect], params: Sequence[FloatArray], segment: int) -> Trace:
        w = self.w_held
        nominal = simulate(self.model, [], [], w)[segment]
        final = simulate(self.model, effects, params, w)[segment]
        trial = self.held_trials[int(w.trial_index[segment])]
        return Trace(
            f"{trial.name}, t = {w.t[segment, 0] - trial.t[0]:.2f} s",
            w.t[segment] - w.t[segment, 0],
            w.q[segment],
            nominal,
            final,
            "position [rad]",
        )

    def state_explained(
        self, effects: Sequence[Effect], params: Sequence[FloatArray], bins: int = 12
    ) -> float:
        """Share of the held-out torque residual (inverse dynamics, after the found torque
        effects) that a function of position and velocity learnt on the fitting trials
        predicts: a 12 x 12 table of mean residuals over (q, q'). Near 0: the leftover is not
        physics of the joint's state, but an input the model does not see."""

        def residual(trials: Sequence[Trial]) -> tuple[FloatArray, FloatArray, FloatArray]:
            model = self.model
            for effect, p in zip(effects, params, strict=True):
                model = effect.adjust(model, p)
            q, qd, r = inverse_dynamics_residual(model, trials)
            for effect, p in zip(effects, params, strict=True):
                r = r - np.broadcast_to(effect.torque(q, qd, p), r.shape)
            return q, qd, r

        q, qd, r = residual(self.fit_trials)
        q_edges = np.quantile(q, np.linspace(0, 1, bins + 1)[1:-1])
        v_edges = np.quantile(qd, np.linspace(0, 1, bins + 1)[1:-1])
        cell = np.digitize(q, q_edges) * bins + np.digitize(qd, v_edges)
        total = np.bincount(cell, r, bins * bins)
        count = np.bincount(cell, minlength=bins * bins)
        table = np.where(count > 0, total / np.maximum(count, 1), 0.0)
        hq, hqd, hr = residual(self.held_trials)
        predicted = table[np.digitize(hq, q_edges) * bins + np.digitize(hqd, v_edges)]
        variance = float(np.var(hr))
        return 1.0 - float(np.var(hr - predicted)) / variance if variance > 0 else 0.0


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


@dataclass
class _Base:
    """The held-out error a round starts from."""

    err: FloatArray
    rmse: float
    aic: float
    floor: float  # the noise floor


@dataclass
class _Step:
    """One or two candidate effects added to those found so far, with all parameters."""

    added: list[Any]
    params: list[FloatArray]  # of the effects found so far, then of ``added``
    err: FloatArray  # held-out
    rmse: float
    aic: float
    gain: float  # share of the held-out error above the noise floor it removes
    result: Any  # the least-squares fit behind the parameters
    meaningful: bool
    joint: bool = False  # ``result`` fitted every parameter, not only those of ``added``
    alone_rmse: list[float] = field(default_factory=list)  # a pair: the first member alone
    alone_aic: list[float] = field(default_factory=list)  # a pair: each member alone
    alternatives: list[str] = field(default_factory=list)

    def new(self) -> list[tuple[Any, FloatArray]]:
        return list(zip(self.added, self.params[len(self.params) - len(self.added) :], strict=True))


def _total(params: Sequence[FloatArray]) -> int:
    return sum(p.size for p in params)


class Discoverer:
    def __init__(
        self,
        problem: Problem,
        *,
        min_improvement: float | None = None,
        progress: Callable[[str], None] = lambda _t: None,
    ) -> None:
        self.problem = problem
        self.min_improvement = (
            problem.min_improvement if min_improvement is None else min_improvement
        )
        self.progress = progress

    @staticmethod
    def _rmse(err: FloatArray) -> float:
        return float(np.sqrt(np.mean(err**2)))

    @staticmethod
    def _aic(err: FloatArray, k: int) -> float:
        n = err.size
        return n * math.log(max(float(np.sum(err**2)), 1e-300) / n) + 2 * k

    def _fit(
        self, effects: list[Any], params: list[FloatArray], new: Any
    ) -> tuple[FloatArray, Any]:
        problem = self.problem
        x0 = np.clip(problem.initial(new), new.lower, new.upper)
        if not new.fittable:
            return x0, None

        def many(xs: Sequence[FloatArray]) -> list[FloatArray]:
            return problem.error_sets([*effects, new], [[*params, x] for x in xs], False)

        def residual(x: FloatArray) -> FloatArray:
            return many([x])[0]

        lower, upper = np.asarray(new.lower, dtype=float), np.asarray(new.upper, dtype=float)

        if x0.size == 1:
            # one parameter: scan its range first. Effects with a threshold (stiction,
            # saturation) change the error in steps, where finite-difference gradients are zero.
            # Then once more between the best point's neighbours, for a threshold's value.
            grid = np.unique(np.r_[np.linspace(lower[0], upper[0], GRID_POINTS), x0])
            for _ in range(2):
                costs = [float(np.sum(r**2)) for r in many([np.array([g]) for g in grid])]
                best = int(np.argmin(costs))
                x0 = np.array([grid[best]])
                grid = np.linspace(grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)], 25)
        result = least_squares(
            residual,
            x0,
            jac=lambda x: _jacobian(many, x, upper),
            bounds=(lower, upper),
            x_scale="jac",
            max_nfev=60,
        )
        if float(np.sum(result.fun**2)) > float(np.sum(residual(x0) ** 2)):
            result.x = x0  # the local refinement did not help: keep the scanned value
        return result.x, result

    def _interval(self, result: Any, x: FloatArray) -> list[tuple[float, float]]:
        if result is None or result.jac is None:
            return [(float(v), float(v)) for v in x]
        dof = max(1, result.fun.size - x.size)
        sigma2 = 2 * result.cost / dof
        try:
            cov = np.linalg.pinv(result.jac.T @ result.jac) * sigma2
        except np.linalg.LinAlgError:
            return [(math.nan, math.nan) for _ in x]
        half = 1.96 * np.sqrt(np.clip(np.diag(cov), 0, None))
        return [(float(v - h), float(v + h)) for v, h in zip(x, half, strict=True)]

    def _where(self, before: FloatArray, after: FloatArray) -> dict[str, Any]:
        gains = {}
        for name, mask in self.problem.phases().items():
            if mask.any():
                gains[name] = float(
                    np.sqrt(np.mean(before[mask] ** 2)) - np.sqrt(np.mean(after[mask] ** 2))
                )
        phase = max(gains, key=lambda k: gains[k]) if gains else "all"
        segment, labels = self.problem.segments()
        count = np.bincount(segment, minlength=len(labels)).clip(1)
        per_segment = np.sqrt(np.bincount(segment, before**2, len(labels)) / count) - np.sqrt(
            np.bincount(segment, after**2, len(labels)) / count
        )
        trial, t0, t1 = labels[int(np.argmax(per_segment))]
        return {
            "phase": phase,
            "rmse_reduction_by_phase_rad": gains,
            "trial": trial,
            "window_s": [round(t0, 4), round(t1, 4)],
        }

    def run(self) -> Report:
        started = time.perf_counter()
        problem = self.problem
        report = Report(problem.nominal, problem.split)
        effects: list[Any] = []
        params: list[FloatArray] = []
        held_err = problem.error(effects, params, True)
        report.heldout_rmse_nominal = self._rmse(held_err)
        remaining = problem.candidates()
        floor = problem.noise_floor()
        closest: _Step | None = None
        while remaining and self._rmse(held_err) > SIGNIFICANT * floor:
            base = _Base(held_err, self._rmse(held_err), self._aic(held_err, _total(params)), floor)
            singles = [self._single(effects, params, cand, base) for cand in remaining]
            step = self._choose([s for s in singles if self._names(s, base)])
            if step is None and base.rmse > LEFTOVER * floor:
                # structure is left that no single effect explains: two missing effects may
                # each explain too little alone (one stands in for the other). Not below: a
                # pair fitted to what is nearly noise explains noise.
                self.progress("no single effect explains it: trying pairs")
                step = self._choose(
                    [s for s in self._pairs(effects, params, singles, base) if self._names(s, base)]
                )
            if step is None:
                # (a candidate refused as not meaningful, e.g. pinned at a bound, is no answer)
                closest = max(
                    (s for s in singles if s.meaningful), key=lambda s: s.gain, default=None
                )
                break
            first_rmse = base.rmse
            for k, cand in enumerate(step.added):
                # a pair: the first is reported with what it removes alone
                after = step.rmse if k == len(step.added) - 1 else step.alone_rmse[k]
                report.findings.append(self._finding(cand, step, base, first_rmse, after))
                first_rmse = after
                self.progress(f"found {cand.name}: {report.findings[-1].evidence}")
            effects = [*effects, *step.added]
            params, held_err = step.params, step.err
            remaining = [c for c in remaining if all(c is not a for a in step.added)]
            if step.joint:  # every parameter refitted: the findings' values and intervals
                intervals = self._interval(step.result, step.result.x)
                self._update_findings(report, effects, params, intervals)
        report.fitted = list(zip(effects, params, strict=True))
        report.final_heldout_rmse = self._rmse(held_err)
        report.unexplained = self._leftover(held_err, effects, params, closest)
        report.seconds = time.perf_counter() - started
        return report

    def _single(
        self, effects: list[Any], params: list[FloatArray], cand: Any, base: _Base
    ) -> _Step:
        """``cand`` added to the effects found so far: its own parameters fitted, then all of
        them together (an effect found earlier may have stood in for part of this one)."""
        self.progress(f"trying {cand.name}")
        x, result = self._fit(effects, params, cand)
        joint, together = self._refit([*effects, cand], [*params, x])
        if together is None:
            return self._step(effects, [*params, x], [cand], result, base)
        step = self._step(effects, joint, [cand], together, base)
        step.joint = True
        return step

    def _step(
        self,
        effects: list[Any],
        params: list[FloatArray],
        added: list[Any],
        result: Any,
        base: _Base,
    ) -> _Step:
        err = self.problem.error([*effects, *added], params, True)
        rmse = self._rmse(err)
        size = _total(params[: len(effects)]) + sum(
            _size(a, p) for a, p in zip(added, params[len(effects) :], strict=True)
        )
        return _Step(
            added=added,
            params=params,
            err=err,
            rmse=rmse,
            aic=self._aic(err, size),
            gain=(base.rmse - rmse) / max(base.rmse - base.floor, 1e-12),
            result=result,
            meaningful=all(
                a.meaningful(p) for a, p in zip(added, params[len(effects) :], strict=True)
            ),
        )

    def _names(self, step: _Step, base: _Base) -> bool:
        """Whether ``step`` names its effects: it removes at least ``min_improvement`` of the
        held-out error above the noise floor, a tenth of the floor at least, improves the
        information criterion by 10, and every effect in it is meaningful (no drift scales near
        1, no fit against a bound); a pair also beats each of its members alone by 10. A missing
        effect that is really there explains most of what is left; one that stands in for
        something else explains part of it."""
        return (
            step.meaningful
            and base.rmse - step.rmse >= 0.1 * base.floor
            and step.gain >= self.min_improvement
            and step.aic < base.aic - 10
            and all(step.aic < a - 10 for a in step.alone_aic)
        )

    @staticmethod
    def _choose(steps: list[_Step]) -> _Step | None:
        """The best step by the information criterion. Steps that explain the held-out data
        alike (within 5 % RMSE) cannot be told apart here: the one with the fewest parameters
        is named, the others are listed as alternatives."""
        if not steps:
            return None
        top = min(steps, key=lambda c: c.aic)
        alike = [c for c in steps if c.rmse <= 1.05 * top.rmse]
        best = min(alike, key=lambda c: (sum(_size(a, p) for a, p in c.new()), c.aic))
        best.alternatives = ["+".join(a.name for a in c.added) for c in alike if c is not best]
        return best

    def _pairs(
        self,
        effects: list[Any],
        params: list[FloatArray],
        singles: list[_Step],
        base: _Base,
    ) -> list[_Step]:
        """Two candidates added together, all parameters fitted jointly from each one's own
        fit: two effects that are both missing may each explain too little alone
        (one stands in for the other)."""
        n = len(effects)
        ranked = sorted(singles, key=lambda c: c.rmse)  # a pair lists the better one first
        fitted: list[tuple[float, _Step, _Step, list[FloatArray], Any]] = []
        for i, first in enumerate(ranked):
            for second in ranked[i + 1 :]:
                added = [*first.added, *second.added]
                self.progress(f"trying {' + '.join(c.name for c in added)}")
                x0 = [*params, *(x for _, x in first.new()), *(x for _, x in second.new())]
                # the pair's own parameters first (the effects found before held)
                own, result = self._refit([*effects, *added], x0, start=n)
                cost = (
                    2 * result.cost
                    if result is not None
                    else float(np.sum(self.problem.error([*effects, *added], own, False) ** 2))
                )
                fitted.append((cost, first, second, own, result))
        fitted.sort(key=lambda f: f[0])
        out = []
        # then, for the best few, everything together
        for _, first, second, own, own_fit in fitted[: PAIR_FINALISTS if n else len(fitted)]:
            added = [*first.added, *second.added]
            joint, result = (own, own_fit) if n == 0 else self._refit([*effects, *added], own)
            step = self._step(effects, joint, added, result, base)
            step.joint = result is not None  # (without it: no intervals)
            step.alone_rmse = [first.rmse]
            step.alone_aic = [first.aic, second.aic]
            out.append(step)
        return out

    def _finding(self, cand: Any, step: _Step, base: _Base, before: float, after: float) -> Finding:
        x = step.params[len(step.params) - len(step.added) + step.added.index(cand)]
        ci = (
            self._interval(step.result, x)
            if not step.joint
            else [(float(v), float(v)) for v in x]  # set from the joint fit afterwards
        )
        together = [a.name for a in step.added if a is not cand]
        return Finding(
            effect=cand.name,
            parameters={n: float(v) for n, v in zip(cand.param_names, x, strict=True)}
            | cand.extra_parameters(x),
            confidence_interval={n: c for n, c in zip(cand.param_names, ci, strict=True)},
            where=self._where(base.err, step.err),
            evidence=(
                f"held-out simulation RMSE {before:.4g} -> {after:.4g} rad "
                f"({100 * (1 - after / before):.0f} % lower) with {x.size} parameter(s)"
                + (
                    f"; found together with {', '.join(together)} (neither explains it alone)"
                    if together
                    else ""
                )
                + (
                    f"; explained alike by {', '.join(step.alternatives)}"
                    if step.alternatives
                    else ""
                )
            ),
            heldout_rmse_before=before,
            heldout_rmse_after=after,
            alternatives=list(step.alternatives),
        )

    def _refit(
        self, effects: Sequence[Any], params: Sequence[FloatArray], start: int = 0
    ) -> tuple[list[FloatArray], Any]:
        """The fittable parameters of ``effects[start:]`` fitted together on the fitting trials
        (the others held), from their current values; (params, least-squares result) or
        (params, None) when there are fewer than two to fit or the joint fit is no better."""
        index = [i for i, e in enumerate(effects) if e.fittable and i >= start]
        if len(index) < 2:
            return list(params), None
        sizes = [params[i].size for i in index]
        lower = np.concatenate([np.asarray(effects[i].lower, dtype=float) for i in index])
        upper = np.concatenate([np.asarray(effects[i].upper, dtype=float) for i in index])
        x0 = np.clip(np.concatenate([params[i] for i in index]), lower, upper)

        def unpack(x: FloatArray) -> list[FloatArray]:
            out, k = list(params), 0
            for i, n in zip(index, sizes, strict=True):
                out[i] = np.array(x[k : k + n])
                k += n
            return out

        def many(xs: Sequence[FloatArray]) -> list[FloatArray]:
            return self.problem.error_sets(effects, [unpack(x) for x in xs], False)

        def residual(x: FloatArray) -> FloatArray:
            return many([x])[0]

        result = least_squares(
            residual,
            x0,
            jac=lambda x: _jacobian(many, x, upper),
            bounds=(lower, upper),
            x_scale="jac",
            max_nfev=40,
        )
        if float(np.sum(result.fun**2)) >= float(np.sum(residual(x0) ** 2)):
            return list(params), None
        return unpack(result.x), result

    @staticmethod
    def _update_findings(
        report: Report,
        effects: Sequence[Any],
        params: Sequence[FloatArray],
        intervals: Sequence[tuple[float, float]],
    ) -> None:
        """Parameters and intervals of the findings from a joint refit (intervals in the order
        of the fittable effects' parameters)."""
        k = 0
        for i, (effect, p) in enumerate(zip(effects, params, strict=True)):
            ci = report.findings[i].confidence_interval
            if effect.fittable:
                ci = dict(zip(effect.param_names, intervals[k : k + p.size], strict=True))
                k += p.size
            report.findings[i] = replace(
                report.findings[i],
                parameters={n: float(v) for n, v in zip(effect.param_names, p, strict=True)}
                | effect.extra_parameters(p),
                confidence_interval=ci,
            )

    def _leftover(
        self,
        err: FloatArray,
        effects: Sequence[Any] = (),
        params: Sequence[FloatArray] = (),
        closest: _Step | None = None,
    ) -> list[dict[str, Any]]:
        """Structure the found effects do not explain: a phase whose residual is well above the
        noise floor, with the frequency where the residual has most power, and the candidate
        that came closest (and how much it would have removed)."""
        floor = self.problem.noise_floor()
        out = []
        peak: float | None = None
        explained: float | None = None
        for name, mask in self.problem.phases().items():
            if mask.sum() < 50:
                continue
            rms = float(np.sqrt(np.mean(err[mask] ** 2)))
            if rms > LEFTOVER * floor:
                if peak is None:
                    peak = self.problem.residual_peak_hz(effects, params)
                    explained = getattr(self.problem, "state_explained", lambda *_: None)(
                        effects, params
                    )
                entry: dict[str, Any] = {
                    "where": {"phase": name},
                    "rmse_rad": rms,
                    "noise_floor_rad": floor,
                    "dominant_frequency_hz": peak,
                    "looks_like": f"residual {rms / floor:.0f}x the noise floor in phase "
                    f"'{name}'; the residual peaks near {peak:.1f} Hz",
                }
                if closest is not None and closest.gain > 0:
                    names = " + ".join(c.name for c in closest.added)
                    entry["closest_candidate"] = {"effect": names, "share_removed": closest.gain}
                    entry["looks_like"] += (
                        f"; the closest candidate, {names}, would remove {closest.gain:.0%} of "
                        "it, too little to name"
                    )
                if explained is not None:
                    entry["state_explained_fraction"] = explained
                    entry["looks_like"] += (
                        f"; position and velocity explain {max(explained, 0.0):.0%} of the "
                        "torque residual on held-out trials"
                        + (
                            " (not a function of the state: an input the model does not see, "
                            "such as a hand or a contact)"
                            if explained < STATE_EXPLAINED
                            else ""
                        )
                    )
                out.append(entry)
        return out


def _jacobian(
    many: Callable[[Sequence[FloatArray]], list[FloatArray]], x: FloatArray, upper: FloatArray
) -> FloatArray:
    """Forward differences of step 1e-3 max(1, |x|) (backwards at the upper bound), the
    shifted points evaluated together with ``x`` in one call of ``many``."""
    h = 1e-3 * np.maximum(1.0, np.abs(x))
    h = np.where(x + h > upper, -h, h)
    shifted = [x + np.eye(x.size)[i] * h[i] for i in range(x.size)]
    base, *moved = many([x, *shifted])
    return np.stack([(m - base) / h[i] for i, m in enumerate(moved)], axis=1)


def _size(effect: Any, x: FloatArray) -> int:
    """Parameters an effect spends, its discrete choices included (cogging's period)."""
    return int(x.size) + int(effect.discrete_choices)


def discover(
    model: NominalModel,
    trials: Sequence[Trial],
    *,
    window_s: float = 0.1,
    candidates: Sequence[Effect] | None = None,
    **kwargs: Any,
) -> Report:
    """The loop on 1-DoF torque-driven trials."""
    if len(trials) < 1:
        raise ModelError("no trials to analyse")
    problem = TorqueDrivenProblem(model, trials, window_s=window_s, candidates=candidates)
    return Discoverer(problem, **kwargs).run()
