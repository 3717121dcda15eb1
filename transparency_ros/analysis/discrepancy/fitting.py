"""Fitting candidate effects: one effect's parameters (a scan of one-parameter effects, then
bounded least squares), several effects' parameters together, 95 % intervals from the Jacobian,
and the error measures the loop compares (RMSE, information criterion)."""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.analysis.discrepancy.problem import Problem

GRID_POINTS = 25
# by how much a model's information criterion (aic) must fall to count as better: a step that
# names its effects, a pair against its members alone, a declared effect, the other search
CRITERION = 10.0


def rmse(err: FloatArray) -> float:
    return float(np.sqrt(np.mean(err**2)))


def aic(err: FloatArray, k: int) -> float:
    n = err.size
    return n * math.log(max(float(np.sum(err**2)), 1e-300) / n) + 2 * k


def fit_candidate(
    problem: Problem,
    effects: list[Any],
    params: list[FloatArray],
    new: Any,
    start: FloatArray | None = None,
) -> tuple[FloatArray, Any]:
    """The parameters of ``new`` added to ``effects`` (theirs held) on the fitting trials, from
    ``start`` (None: the problem's initial values of ``new``): (parameters, least-squares
    result); the result is None for an effect with nothing to fit."""
    # an effect with a choice to make from the data (cogging's period) scans for it against
    # the effects found so far
    scan = getattr(new, "scan", None)
    if start is None:
        start = problem.initial(new) if scan is None else scan(problem, effects, params)
    x0 = np.clip(start, new.lower, new.upper)
    if not new.fittable:
        return x0, None

    def many(xs: Sequence[FloatArray]) -> list[FloatArray]:
        return problem.error_sets([*effects, new], [[*params, x] for x in xs], False)

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
    result, start_cost = _bounded_least_squares(many, x0, lower, upper, max_nfev=60)
    if float(np.sum(result.fun**2)) > start_cost:
        result.x = x0  # the local refinement did not help: keep the scanned value
    return result.x, result


def refit(
    problem: Problem, effects: Sequence[Any], params: Sequence[FloatArray], start: int = 0
) -> tuple[list[FloatArray], Any]:
    """The fittable parameters of ``effects[start:]`` fitted together on the fitting trials
    (the others held), from their current values; (params, least-squares result) or
    (params, None) when there is nothing to fit but the last effect (just fitted alone) or the
    joint fit is no better. An effect with nothing to fit (the shuttle's weight, an encoder's
    lattice) added after one that was fitted without it refits that one: a drift of b_v
    fitted without the weight had set the Coulomb torque to 0 to stand in for it, and the
    weight, added on top unfitted, was refused as making the fit worse (zoo 9331)."""
    index = [i for i, e in enumerate(effects) if e.fittable and i >= start]
    if not index or index == [len(effects) - 1]:
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
        return problem.error_sets(effects, [unpack(x) for x in xs], False)

    result, start_cost = _bounded_least_squares(many, x0, lower, upper, max_nfev=40)
    if float(np.sum(result.fun**2)) >= start_cost:
        return list(params), None
    return unpack(result.x), result


def rescanned(
    problem: Problem,
    effects: Sequence[Any],
    params: Sequence[FloatArray],
    *,
    pair: Sequence[Any],
    own: Sequence[FloatArray],
    result: Any,
    cost: float,
    alone: Sequence[FloatArray],
) -> tuple[list[Any], list[FloatArray], Any]:
    """A pair (``pair``, fitted together to ``own``, ``result``, its ``cost`` on the fitting
    trials, with ``effects`` held at ``params``) whose member chooses from the data (cogging's
    period, ``scan``) chose without the other: that member scanned and fitted again beside
    the other at its fit alone (``alone``: each member's), as a copy (the candidate keeps its
    own choice for the other pairs), and the pair refitted from there; kept where it fits the
    fitting trials better (the cost given, not simulated again: a pair without a wave costs
    nothing here).
    Scanned alone, a wave's period stands in for the other member too (zoo 11317: a cogging
    of 63 periods and an offset; alone, a period whose wave leans the arm as the offset does
    took the scan). Beside the other at the pair's fit, made with that period, the scan can
    choose as wrongly: on this project's own simulated cogging of 63 and 120 periods with an
    offset, 161 and 57 beside the pair's offset, 64 and 119 beside the offset fitted alone."""
    n = len(effects)
    best = (list(pair), list(own), result, cost)
    for k, member in enumerate(pair):
        if getattr(member, "scan", None) is None:
            continue
        other = 1 - k
        twin = copy.copy(member)
        x, _ = fit_candidate(problem, [*effects, pair[other]], [*params, alone[other]], twin)
        added = list(pair)
        added[k] = twin
        start = list(own)
        start[n + k] = x
        again, again_fit = refit(problem, [*effects, *added], start, start=n)
        cost_again = fit_cost(problem, [*effects, *added], again, again_fit)
        if cost_again < best[3]:
            best = (added, again, again_fit, cost_again)
    return best[0], best[1], best[2]


def fit_cost(
    problem: Problem, effects: Sequence[Any], params: Sequence[FloatArray], result: Any
) -> float:
    """The sum of squared errors on the fitting trials: the least-squares result's (None:
    simulated)."""
    if result is not None:
        return 2 * float(result.cost)
    return float(np.sum(problem.error(list(effects), list(params), False) ** 2))


def _bounded_least_squares(
    many: Callable[[Sequence[FloatArray]], list[FloatArray]],
    x0: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    max_nfev: int,
) -> tuple[Any, float]:
    """Bounded least squares on the error ``many([x])[0]``, its Jacobian from forward
    differences evaluated in one batch; (result, the cost at ``x0``), so that the caller keeps
    ``x0`` where the fit does not improve on it."""

    def residual(x: FloatArray) -> FloatArray:
        return many([x])[0]

    result = least_squares(
        residual,
        x0,
        jac=lambda x: jacobian(many, x, upper),
        bounds=(lower, upper),
        x_scale="jac",
        max_nfev=max_nfev,
    )
    result.lower, result.upper = lower, upper  # (for the intervals: what is held at a bound)
    return result, float(np.sum(residual(x0) ** 2))


BOUND_HELD = 1e-4  # a parameter this close to a bound (a share of its range) is held there


def interval(result: Any, x: FloatArray) -> list[tuple[float, float]]:
    """95 % intervals of ``x`` from the least-squares fit's Jacobian (none: the value itself).
    A simulation's residual is not white: what the model still misses runs through many
    samples. The covariance is widened by the residual's own correlation, (1 + rho) / (1 - rho)
    for its lag-1 autocorrelation rho (an AR(1) error: n samples weigh as n (1 - rho) /
    (1 + rho) independent ones); with white-noise intervals, 4 in 9 zoo parameters were
    covered. A parameter the fit holds at a bound of its range (an arm on the flank of its dead
    band) is taken as known there: the others' intervals are the ones given it (a Jacobian
    at a bound says nothing of the side the fit could not go to)."""
    if result is None or result.jac is None:
        return [(float(v), float(v)) for v in x]
    held = _held(result, x)
    free = np.ones(x.size, dtype=bool) if held is None else ~held[0]
    dof = max(1, result.fun.size - int(free.sum()))
    sigma2 = 2 * result.cost / dof * correlation_inflation(result.fun, int(free.sum()))
    jac = np.asarray(result.jac)[:, free]
    try:
        cov = np.linalg.pinv(jac.T @ jac) * sigma2
    except np.linalg.LinAlgError:
        return [(math.nan, math.nan) for _ in x]
    half = np.zeros(x.size)
    half[free] = 1.96 * np.sqrt(np.clip(np.diag(cov), 0, None))
    return [(float(v - h), float(v + h)) for v, h in zip(x, half, strict=True)]


def _held(result: Any, x: FloatArray) -> tuple[npt.NDArray[np.bool_], FloatArray] | None:
    """Which of ``x`` the fit holds at a bound of its range (within ``BOUND_HELD`` of the
    range), and that tolerance; None where the fit has no bounds for ``x``. (The fit keeps x
    strictly inside: 1 - 2e-6 of a range of 2 is on the bound.)"""
    lower, upper = getattr(result, "lower", None), getattr(result, "upper", None)
    if lower is None or upper is None or np.size(lower) != x.size:
        return None
    tol = BOUND_HELD * (upper - lower)
    return (x - lower <= tol) | (upper - x <= tol), tol


def held_at(result: Any, x: FloatArray) -> Callable[[int, float], bool]:
    """Whether the fit holds parameter ``i`` at a bound of its range that is ``value`` (held
    as :func:`interval` takes it)."""
    held = _held(result, x)
    return lambda i, value: bool(
        held is not None and held[0][i] and abs(x[i] - value) <= held[1][i]
    )


def correlation_inflation(residual: FloatArray, k: int) -> float:
    """How much a correlated residual widens an interval's variance: (1 + rho) / (1 - rho) for
    its lag-1 autocorrelation rho, at most as if only k + 1 samples were independent."""
    r = np.asarray(residual, dtype=float)
    energy = float(r @ r)
    if r.size < 3 or energy <= 0.0:
        return 1.0
    rho = float(np.clip((r[:-1] @ r[1:]) / energy, 0.0, 1.0))
    most = max(1.0, r.size / (k + 1))
    return float(min((1 + rho) / max(1 - rho, 1e-12), most))


def jacobian(
    many: Callable[[Sequence[FloatArray]], list[FloatArray]], x: FloatArray, upper: FloatArray
) -> FloatArray:
    """Forward differences of step 1e-3 max(1, |x|) (backwards at the upper bound), the
    shifted points evaluated together with ``x`` in one call of ``many``."""
    h = 1e-3 * np.maximum(1.0, np.abs(x))
    h = np.where(x + h > upper, -h, h)
    shifted = [x + np.eye(x.size)[i] * h[i] for i in range(x.size)]
    base, *moved = many([x, *shifted])
    return np.stack([(m - base) / h[i] for i, m in enumerate(moved)], axis=1)


def parameter_count(effect: Any, x: FloatArray) -> int:
    """Parameters an effect spends, its discrete choices included (cogging's period)."""
    return int(x.size) + int(effect.discrete_choices)
