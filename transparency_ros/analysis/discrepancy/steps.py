"""What the discovery loop (:mod:`discover`) compares: the held-out error a round starts from
(:class:`Base`), one or two candidates added to the model with all parameters (:class:`Step`),
and which candidates are variants of one effect (:func:`same`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from transparency_ros.analysis.discrepancy.fitting import held_at, interval, parameter_count
from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.analysis.discrepancy.problem import SIGNIFICANT

ALIKE = 1.05  # held-out RMSEs this close cannot be told apart (choose, Discoverer._single)
EXPECTED_MARGIN = 1.10  # an effect the recording predicts is preferred this close to the best
# A wave chosen among every period the recording can show (cogging) removes some of any error.
# Where its period stands out of the scan (its prominence: what its waves remove against what
# the median period's remove, drop_cogging.DropCogging.scan) by prominent_wave(M) or more, M
# the periods the scan could tell apart, over WAVE_CYCLES periods of the arm's travel at least
# (fewer is a smooth torque that any low period imitates), the share of the error it must
# remove is waived: what is left beside it is the model's own error elsewhere (the contact and
# friction laws), which no wave takes. The threshold is a periodogram's peak test with its
# look-elsewhere correction: where no period is singled out, the error a period's two waves
# remove is about exponential (two degrees of freedom), whose median is ln 2 of its mean, so
# the largest of M independent periods passes t times the median with probability about
# M 2^-t; t = log2(M / WAVE_FALSE_ALARM) (against a median itself taken over the M periods,
# and so scattered, 1.8-4.4 % for M of 100-10: test_discrepancy). A short travel tells few
# periods apart (the scan's resolution is a period's drift of one whole period over the
# travel): M 7-30 on the zoo, thresholds 9.4-11.6. Measured on zoo campaigns with and without
# a hidden cogging (benchmarks/prominence_calibration.py; 500 campaigns, 449 without a
# cogging: none more named than under the flat 15 it replaces, the largest such wave 0.73 of
# its threshold; a wave over 1-1.25 periods of travel, the scan's coarsest, stands out up to
# 157 times; over 1.25-2 periods no more than 7.7, as over 2 and more; hence 1.5).
WAVE_FALSE_ALARM = 0.01
WAVE_CYCLES = 1.5
# A wave whose period does not stand out may still be the motor's: where every trial, fitted
# on its own, shows the same wave (its ``spread``, drop_cogging.DropCogging.spread, at most
# REPLICATED_SPREAD) over REPLICATED_CYCLES periods of travel at least, the share is waived
# too. Below that, a wave stands in for a smooth torque that every trial shows alike.
REPLICATED_SPREAD = 0.5
REPLICATED_CYCLES = 2.5


@dataclass
class Base:
    """The held-out error a round starts from."""

    err: FloatArray
    rmse: float
    aic: float
    floor: float  # the noise floor
    # the model it is the error of (the effects found so far, their parameters)
    effects: list[Any] = field(default_factory=list)
    params: list[FloatArray] = field(default_factory=list)


@dataclass
class Step:
    """One or two candidate effects added to those found so far, with all parameters."""

    added: list[Any]
    params: list[FloatArray]  # of the effects found so far, then of ``added``
    err: FloatArray  # held-out
    rmse: float
    aic: float
    gain: float  # share of the held-out error above the noise floor it removes
    judged: tuple[float, float, float]  # (RMSE before, after, floor) the gain is judged on
    result: Any  # the least-squares fit behind the parameters
    meaningful: bool
    joint: bool = False  # ``result`` fitted every parameter, not only those of ``added``
    alone_rmse: list[float] = field(default_factory=list)  # a pair: the first member alone
    alone_aic: list[float] = field(default_factory=list)  # a pair: each member alone
    alternatives: list[str] = field(default_factory=list)
    # the steps ``alternatives`` names (choose): their fitted values go into the finding
    alike: list[Any] = field(default_factory=list)
    # the first of ``alike`` that only its ``yields_to`` put behind this one (choose)
    behind: Any = None
    shown: bool = False  # stands for a declared effect the recording shows (see _each_added)
    elsewhere: str = ""  # what a second channel showed of it (a problem's shows_elsewhere)
    # of an added effect whose choice was made from the data by a scan (cogging's period):
    # (its prominence, the periods the arm's travel spans, its spread over the trials: NaN
    # where not measured, the periods the scan could tell apart) when the step was made (see
    # scan_facts)
    scanned: list[tuple[float, float, float, float]] = field(default_factory=list)

    def new(self) -> list[tuple[Any, FloatArray]]:
        return list(zip(self.added, self.params[len(self.params) - len(self.added) :], strict=True))


def null_inside(step: Step) -> bool:
    """Whether the 95 % interval of an added effect holds its value of no effect
    (``null``: no backlash, no delay; NaN: any value, cogging's phase) for every
    parameter: the data do not tell it from nothing, however much the fitted value
    removes. A parameter the fit holds at a bound of its range that is its null holds it
    too (its interval is the bound itself): the fit would go past no effect if it could.
    On the independent rig, rebounds fitted at e 0.000 (0.000 to 0.000) were named so.
    The fitted parameters of the added effects are the last of the fit's."""
    if step.result is None or getattr(step.result, "jac", None) is None:
        return False
    ci = interval(step.result, step.result.x)
    at_null = held_at(step.result, step.result.x)
    end = len(ci)
    for effect, x in reversed(step.new()):
        if not getattr(effect, "fittable", True):
            continue
        own, end = ci[end - x.size : end], end - x.size
        null = getattr(effect, "null", None)
        if (
            null is not None
            and own
            and all(
                math.isnan(z) or lo <= z <= hi or at_null(end + i, z)
                for i, ((lo, hi), z) in enumerate(zip(own, null, strict=True))
            )
        ):
            return True
    return False


def driven_to_bound(effects: list[Any], params: list[FloatArray], base: Base) -> bool:
    """Whether a joint refit (``params``: of ``effects``, then of what is added) holds an
    effect named before at a bound of its range where the model it was added to
    (``base``) did not: what is added has taken over what that effect explained, and the
    two together stand in for something neither is. Only effects that say so
    (``pinned_by_refit``; the robot's, whose fits are judged meaningful by their bounds
    alone) are checked, where fitted. On robot zoo 1071 (an offset and Coulomb friction concealed,
    link 2's inertial terms 0.57 of the URDF's) a payload at link 2, searched for at 1.25
    noise floors, took the error to 0.91 with link 2's scale refitted from 0.57 to its
    bound of 0.2; taken out again on the final model, the scale came back at its bound and
    was dropped, and every effect after it, 5.4 floors left."""
    if base.effects is not effects and [id(e) for e in base.effects] != [id(e) for e in effects]:
        return False
    for effect, before, after in zip(effects, base.params, params, strict=False):
        held = getattr(effect, "pinned_by_refit", None)
        if held is None or not getattr(effect, "fittable", True):
            continue  # (a value read off the recording is not refitted)
        if held(after) and not held(before):
            return True
    return False


def share_removed(before: float, after: float, floor: float) -> float:
    """The share of the error above its noise floor that a step removes (``Step.gain``): of
    ``before`` - ``floor``; where ``before`` is at or under the floor already, of all of it.
    A floor is an estimate: an error under it is not noise alone where a step takes it well
    below (a 6 ms command delay took a robot joint's error from 0.93 to 0.35 of its floor,
    robot zoo 928), and a share of what lies above it, max(before - floor, 1e-12) as it was,
    let any removal pass there (zoo_12214: a 0.25 ms delay that took the encoder's error
    from 0.279 to 0.204 mrad, under its floor of 0.443, had a share of 7.5e7 and was named
    where nothing was hidden; of all of it, 0.27)."""
    if before > floor:
        return (before - after) / (before - floor)
    return (before - after) / before if before > 0 else 0.0


def short_of_floor(step: Step) -> bool:
    """Whether ``step`` is judged on an error already within ``SIGNIFICANT`` times its noise
    floor and leaves it above the floor. Where a problem searches on below that
    (``RobotProblem.to_the_floor``), an effect must take what is left there down to the
    floor: a small share of a small excess over an estimated floor is no evidence (on robot
    zoo 1036, searched on, a payload of 0.1 kg at 0.45 m took the error from 1.35 to 1.16
    floors, a share of 0.53 of the excess, in place of nothing concealed), while the effects
    the search had stopped short of take it well below (1034: a sensor delay of 9.6 ms, from
    1.43 to 0.73 floors)."""
    before, after, floor = step.judged
    return before <= SIGNIFICANT * floor and after > floor


def stood_in(step: Step, base: Base) -> bool:
    """Whether a declared effect (its size read off the recording, nothing fitted of it) that
    ``step`` adds explains the held-out data as well (within ``ALIKE``) or better once the
    effects named before it are refitted beside it, and one of their values leaves its 95 %
    interval in that refit: that effect had stood in for the declared one, which the
    recording says is there. On zoo_12556 (a b_v drift x1.66, an offset of -0.071 N m, the
    shuttle's weight of 0.53 N m) no single effect was named, the pair of the drift and an
    offset was, at 0.436 N m: the offset had taken the weight, which then improved the fit by
    nothing, a constant torque already in it."""
    if not step.joint or getattr(step.result, "jac", None) is None:
        return False
    if step.rmse > ALIKE * base.rmse:
        return False
    ci, k = interval(step.result, step.result.x), 0
    for effect, before in zip(base.effects, base.params, strict=True):
        if not effect.fittable:
            continue
        own, k = ci[k : k + before.size], k + before.size
        if any(not lo <= v <= hi for v, (lo, hi) in zip(before, own, strict=True)):
            return True
    return False


def prominent_wave(independent: float) -> float:
    """The prominence a scanned wave's period needs to stand out of ``independent`` periods
    the scan could tell apart, at a false-alarm rate of WAVE_FALSE_ALARM (see above)."""
    return math.log2(max(independent, 1.0) / WAVE_FALSE_ALARM)


def share_needed(step: Step, uniform: float) -> float:
    """The share of the error above the floor ``step`` must remove (Discoverer._names):
    ``uniform``; none for a single wave whose period stands out of its scan
    (``prominent_wave``, over ``WAVE_CYCLES`` periods of travel at least) or that every
    trial shows alike (``REPLICATED_SPREAD``, over ``REPLICATED_CYCLES`` periods at least)."""
    if len(step.added) == 1 and step.scanned:
        prominence, cycles, spread, independent = step.scanned[0]
        if (prominence >= prominent_wave(independent) and cycles >= WAVE_CYCLES) or (
            cycles >= REPLICATED_CYCLES and spread <= REPLICATED_SPREAD
        ):
            return 0.0
    return uniform


def scan_facts(
    problem: Any, effects: list[Any], added: list[Any], params: list[FloatArray]
) -> list[tuple[float, float, float, float]]:
    """``Step.scanned`` of the effects ``added`` to ``effects`` (all parameters ``params``):
    for each whose choice a scan made, (prominence, periods of travel, spread, periods the
    scan could tell apart). The spread
    (a refit per trial) is measured for a single wave over ``WAVE_CYCLES`` periods of travel
    or more (NaN otherwise): the rule asks for it from ``REPLICATED_CYCLES`` on, and the
    calibration (benchmarks/prominence_calibration.py) logs it from ``WAVE_CYCLES`` to show
    why not lower. It is measured whether or not the step meets the share without it (two
    batched simulations a cogging step, beside the scan's dozens)."""
    out = []
    for a in added:
        if getattr(a, "prominence", None) is None:
            continue
        cycles = float(getattr(a, "wave_cycles", 0.0))
        independent = float(getattr(a, "independent_periods", 1.0))
        spread: Callable[..., float] | None = getattr(a, "spread", None)
        spread_value = math.nan
        if spread is not None and len(added) == 1 and cycles >= WAVE_CYCLES:
            spread_value = spread(problem, effects, params)
        out.append((float(a.prominence), cycles, spread_value, independent))
    return out


def not_named(remaining: list[Any], effects: list[Any]) -> list[Any]:
    """The candidates of ``remaining`` none of whose variants is among ``effects``."""
    return [c for c in remaining if not any(same(c, e) for e in effects)]


def total(params: Sequence[FloatArray]) -> int:
    return sum(p.size for p in params)


def same(a: Any, b: Any) -> bool:
    """Whether two candidates are variants of one effect (a band with its start fitted, and
    with the arm on its far flank): once one is named the others leave the search, and they
    are never paired. Variants are told by name, so the contact spring and the hub-arm spring
    (both ``structural_compliance``) are variants too."""
    return bool(a.name == b.name)


def choose(
    steps: list[Step], expected: Callable[[Any, FloatArray], bool], tolerance: float = ALIKE
) -> Step | None:
    """The best step by the information criterion. Steps that explain the held-out data
    alike (within 5 % RMSE, or both down to the noise floor they are judged against) cannot
    be told apart here: the one with the fewest parameters is named, the others are listed
    as alternatives. (On the load cell of zoo_10384, a drift and an offset left 0.31 and 0.49
    of its noise: the drift, with two terms that moved 1-4 %, was named; the offset was
    hidden.) Between steps of as many parameters, one whose fitted values the recording
    itself predicts comes first (``expected`` of the problem: on a drop test, a payload of
    the shuttle's own m g r, which a constant offset imitates at small arm angles, or an
    offset that held the arm away from theta_d before contact), and such a step is
    considered up to 10 % behind the best. Then a candidate that ``yields_to`` others (a
    rebound off the contact, which a ring of a compliant arm also makes; a drift of the
    Coulomb torque alone, which an offset imitates) comes after them. ``tolerance``: the
    RMSE ratio taken as alike (benchmarks/alike_calibration.py tries others)."""
    if not steps:
        return None
    top = min(steps, key=lambda c: c.aic)
    # (two that both explain the held-out data down to its noise floor are alike too)
    at_floor = top.judged[1] <= top.judged[2]
    alike = [
        c for c in steps
        if c.rmse <= tolerance * top.rmse or (at_floor and c.judged[1] <= c.judged[2])
    ]  # fmt: skip
    # what the recording predicts may be 10 % behind the best and still be preferred
    predicted = [
        c for c in steps
        if c.rmse <= EXPECTED_MARGIN * top.rmse and all(expected(a, p) for a, p in c.new())
    ]  # fmt: skip
    if predicted and not any(c in predicted for c in alike):
        alike = [*alike, *predicted]

    def order(c: Step) -> tuple[int, bool, int, float]:
        return (
            sum(parameter_count(a, p) for a, p in c.new()),
            not all(expected(a, p) for a, p in c.new()),
            max(getattr(a, "yields_to", 0) for a in c.added),
            c.aic,
        )

    best = min(alike, key=order)
    best.alike = [c for c in alike if c is not best]
    best.behind = next(
        (c for c in best.alike if order(c)[:2] == order(best)[:2] and order(c)[2] > order(best)[2]),
        None,
    )
    best.alternatives = ["+".join(a.name for a in c.added) for c in best.alike]
    return best
