"""The motor's cogging as a drop-test candidate (:class:`DropCogging`): its period is chosen from
the data by a linearized scan over every period the recordings can show, its size and phase
fitted (see :mod:`transparency_ros.analysis.discrepancy.drop_effects` for the others)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from transparency_ros.analysis.discrepancy.drop_effects import DropEffect
from transparency_ros.analysis.discrepancy.drop_physics import DropPhysics
from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.analysis.discrepancy.problem import hook

# cogging periods per output revolution tried: from where the positions the arm visited span
# one whole period (less of a wave is a constant torque and a spring there: 2 periods per
# revolution took up a Stribeck hump on an independent rig, and on the zoo's fresh seeds
# 9600-9699 four of five waves named where none was hidden had 8-14 periods, 0.5-0.8 of a
# period over the arm's travel, in place of a hidden offset or rebound) and 2 at
# least (1 is a weight's), up to where a period spans COGGING_COUNTS encoder counts (a finer
# wave is not seen), at most
MOST_COGGING_PERIODS = 400
COGGING_COUNTS = 8
COGGING_PROBE_NM = 0.01  # the wave's size the scan linearizes at
COGGING_FINALISTS = 5  # periods of the linear scan simulated at their fitted sizes
# the linear scan first tries every few periods: waves of N and N + d periods drift apart by
# d times the arm's travel over it, and at a drift x of COGGING_DRIFT_RAD the two still share
# sin(x / 2) / (x / 2) = 0.97 of their shape (the free phase centres the drift); the best few
# are then scanned at every period around them
COGGING_DRIFT_RAD = math.pi / 4
# the waves DropCogging.spread fits per trial: none, a sine and a cosine of the probe's size
PROBES = ((0.0, 0.0), (COGGING_PROBE_NM, 0.0), (COGGING_PROBE_NM, math.pi / 2))
SPREAD_CAP = 3.0  # a trial's wave this many times the fitted one's size off counts as this

if TYPE_CHECKING:
    from transparency_ros.analysis.discrepancy.drop import DropProblem


class DropCogging(DropEffect):
    """The motor's cogging: A sin(N theta + phase) in the rig's theta sense, at the motor's
    true position. N (periods per output revolution) is a choice made from the data by
    :meth:`scan`; A and the phase are fitted. Its null value is A = 0 (any phase)."""

    def __init__(self) -> None:
        super().__init__(
            "cogging",
            ("amplitude_nm", "phase_rad"),
            (0.0, -2 * math.pi),
            (1.0, 2 * math.pi),
            discrete_choices=1,
            null=(0.0, math.nan),
        )
        self.periods = 0
        # what the last scan saw of its period (see scan): the chosen period's share of the
        # error against the median period's, and the periods the arm's travel spans
        self.prominence: float | None = None
        self.wave_cycles = 0.0
        # the periods the scan could tell apart: its range of N over its resolution (two N
        # whose waves drift one whole period apart over the travel, 2 pi / span)
        self.independent_periods = 1.0

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        return with_cogging(ph, float(p[0]), float(p[1]), self.periods)

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        return {"periods_per_rev": float(self.periods)}

    def scan(
        self, problem: DropProblem, effects: Sequence[DropEffect], params: Sequence[FloatArray]
    ) -> FloatArray:
        """Choose N, and start A and the phase, from the fitting trials: for every few N
        (``COGGING_DRIFT_RAD``), then every N around the best few, the error's response to a
        small sine wave and a small cosine wave (simulated, all N in one run), and the two
        waves' sizes that remove most of the error (linear least squares); the N whose waves,
        simulated, leave the least error is kept. Its ``prominence``: the error its waves
        remove (linear) against what the median N of the first pass removes, a periodogram's
        peak against its level (see Discoverer._names). It is high where the load cell shows
        a wave during the ride (the zoo's hidden coggings: 18-139) and low on the encoder,
        whose error a wave makes mostly where the arm is slow, and there any period makes
        one alike (2 on this project's own simulated wave). (Every N once, as before the
        strides, took half of a campaign's run time: 8.5-13 s of 15-30 s on
        zoo_10902-10904.)"""
        count = problem.encoder_count
        finest = MOST_COGGING_PERIODS
        if count > 0:
            finest = min(finest, int(2 * math.pi / (COGGING_COUNTS * count)))
        span = max(problem.position_span, 1e-9)
        coarsest = max(2, math.ceil(2 * math.pi / span))
        finest = max(finest, coarsest)
        # (every N within stride / 2 of a sampled one: a drift of COGGING_DRIFT_RAD at most)
        stride = max(1, int(2 * COGGING_DRIFT_RAD / span))
        # every N's two waves in one simulation: each set carries its own N
        probe = [*effects, _CoggingProbe()]
        sampled = sorted({*range(coarsest, finest + 1, stride), finest})
        # (the error without a wave simulated with the first pass's waves)
        base, linear = _linear_scan(problem, probe, params, None, sampled, largest=self.upper[0])
        # what a period the data do not single out removes: the median of the first pass
        typical = float(np.median([linear[n][0] for n in sampled]))
        if stride > 1:
            best = sorted(linear, key=lambda n: -linear[n][0])[:COGGING_FINALISTS]
            around = {
                m
                for n in best
                for m in range(max(coarsest, n - stride + 1), min(finest, n + stride - 1) + 1)
            }
            linear |= _linear_scan(
                problem, probe, params, base, sorted(around - set(linear)), largest=self.upper[0]
            )[1]
        # the linear prediction errs where the wave moves the arm by a good part of its period:
        # the best few and their neighbours (N is seen to within a period or two over a short
        # swing) simulated at their sizes, the best kept
        ranked = sorted(linear, key=lambda n: -linear[n][0])[:COGGING_FINALISTS]
        # (each also at the probe's size: a wave the linear fit makes too large)
        tried = [
            (m, np.array([size, linear[m][1][1]]))
            for m in sorted({m for n in ranked for m in range(n - 2, n + 3) if m in linear})
            for size in {linear[m][1][0], min(linear[m][1][0], COGGING_PROBE_NM)}
        ]
        costs = [
            float(np.sum(e**2))
            for e in problem.error_sets(probe, [[*params, np.r_[x, m]] for m, x in tried], False)
        ]
        self.periods, start = tried[int(np.argmin(costs))]
        chosen = linear[self.periods][0]
        self.prominence = chosen / typical if typical > 0 else (math.inf if chosen > 0 else 0.0)
        self.wave_cycles = self.periods * span / (2 * math.pi)
        self.independent_periods = max(1.0, (finest - coarsest) * span / (2 * math.pi))
        return start

    def spread(
        self, problem: DropProblem, effects: Sequence[DropEffect], params: Sequence[FloatArray]
    ) -> float:
        """How far the wave each trial shows on its own lies from the wave fitted to all of
        them (``params``: the effects' parameters, this wave's last), as a share of its size:
        each trial's size and phase of the wave at this period (linear least squares on its
        own error, fitting and held-out trials alike), its distance from the fitted wave over
        the fitted wave's size (at most SPREAD_CAP), weighted by the error each trial's own
        wave removes. A cogging is the motor's: every trial shows the same wave, whatever
        else the model misses (0.10-0.46 where the scan found a hidden cogging's period, on
        zoo campaigns 11300-11399 and 11727). A wave that stands in for something else is a
        different one in each trial (over 2.5 periods of travel and more where none is hidden,
        11300-11499 and 11700-11799: 0.56 and 0.69 the least, most 1.2-3); over fewer
        periods a wave stands in for a smooth torque that every trial shows alike (0.15-0.3
        at 1.7-1.9 periods). NaN where the problem does not say which trial each element is
        of (the load cell's bins). See benchmarks/prominence_calibration.py."""
        index = hook(problem, "trial_index")
        amplitude, phase = float(params[-1][0]), float(params[-1][1])
        if index is None or amplitude <= 0:
            return math.nan
        fitted = amplitude * np.array([math.cos(phase), math.sin(phase)]) / COGGING_PROBE_NM
        before = list(params[:-1])
        sets = [[*before, np.array([size, shift, self.periods])] for size, shift in PROBES]
        weights, distances = [], []
        for held in (False, True):
            base, sine, cosine = problem.error_sets([*effects, _CoggingProbe()], sets, held)
            trial = index(held)
            for i in np.unique(trial):
                m = trial == i
                basis = np.stack([sine[m] - base[m], cosine[m] - base[m]], axis=1)
                own = np.linalg.lstsq(basis, -base[m], rcond=None)[0]
                left = base[m] + basis @ own
                weights.append(max(float(base[m] @ base[m] - left @ left), 0.0))
                distances.append(
                    min(float(np.linalg.norm(own - fitted) / np.linalg.norm(fitted)), SPREAD_CAP)
                )
        total = sum(weights)
        return float(np.dot(weights, distances) / total) if total > 0 else math.nan


def _linear_scan(
    problem: DropProblem,
    probe: list[DropEffect],
    params: Sequence[FloatArray],
    base: FloatArray | None,
    periods: Sequence[int],
    *,
    largest: float,
) -> tuple[FloatArray, dict[int, tuple[float, FloatArray]]]:
    """For each N of ``periods``: the error's response to a small sine wave and a small cosine
    wave (simulated, all N in one run), the two waves' sizes that remove most of the error
    ``base`` (linear least squares), and the error they remove. ``base`` None: the error
    without a wave is simulated in the same run. Returns (base, {N: (removed, (A, phase))})."""
    sets = [] if base is not None else [[*params, np.array([0.0, 0.0, periods[0]])]]
    for n in periods:
        sets += [
            [*params, np.array([COGGING_PROBE_NM, 0.0, n])],
            [*params, np.array([COGGING_PROBE_NM, math.pi / 2, n])],
        ]
    errors = problem.error_sets(probe, sets, False) if sets else []
    if base is None:
        base, errors = errors[0], errors[1:]
    linear: dict[int, tuple[float, FloatArray]] = {}
    for k, n in enumerate(periods):
        basis = np.stack([errors[2 * k] - base, errors[2 * k + 1] - base], axis=1)
        (a, b), *_ = np.linalg.lstsq(basis, -base, rcond=None)
        removed = float(base @ base - np.sum((base + basis @ np.array([a, b])) ** 2))
        a, b = a * COGGING_PROBE_NM, b * COGGING_PROBE_NM
        linear[n] = (removed, np.array([min(math.hypot(a, b), largest), math.atan2(b, a)]))
    return base, linear


class _CoggingProbe(DropEffect):
    """Cogging of any N for :meth:`DropCogging.scan`: parameters (A, phase, N)."""

    def __init__(self) -> None:
        super().__init__("cogging", ("amplitude_nm", "phase_rad", "periods_per_rev"), (), ())

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        return with_cogging(ph, float(p[0]), float(p[1]), float(p[2]))


def with_cogging(ph: DropPhysics, amplitude: float, phase: float, periods: float) -> DropPhysics:
    """``ph`` with A sin(N theta + phi) in the rig's sense: A sin(N q + sense phi) in the
    model's (q = sense theta, and torques alike)."""
    sense = np.asarray(ph.sense, dtype=float)
    return replace(
        ph, cogging_nm=amplitude, cogging_periods=periods, cogging_phase_rad=sense * phase
    )
