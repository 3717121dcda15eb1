"""A declared effect (its size read off the recording) named where an effect fitted before it
had taken its place (steps.stood_in): refitted beside it, the data are explained alike and
that effect's value leaves its 95 % interval (zoo_12556: an offset fitted at 0.436 N m took
the shuttle's weight of 0.53 N m; with the weight, -0.071, the truth)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from transparency_ros.analysis.discrepancy.fitting import aic
from transparency_ros.analysis.discrepancy.steps import Base, Step, stood_in

RNG = np.random.default_rng(7)
ANGLE = np.linspace(0.0, 0.4, 400)  # the arm's angle through a recording [rad]
NOISE = 0.002
WEIGHT = 0.53  # the declared torque, m g r cos(angle) [N m]


def _torque(offset: float, weight: float, slope: float) -> np.ndarray:
    return offset + weight * np.cos(ANGLE) + slope * ANGLE


def _fit(data: np.ndarray, weight: float, effect: str) -> tuple[np.ndarray, Any]:
    """The fitted effect (an offset or a slope) with the weight held at ``weight``."""

    def residual(x: np.ndarray) -> np.ndarray:
        offset, slope = (x[0], 0.0) if effect == "offset" else (0.0, x[0])
        return _torque(offset, weight, slope) - data

    result = least_squares(residual, np.array([0.0]))
    return result.x, result


def _case(
    truth_weight: float, effect: str, truth_offset: float = -0.071, declared: float = WEIGHT
) -> bool:
    """Whether the declared weight (``declared`` N m) stood in for: data with ``truth_weight``
    and ``truth_offset``, the model before it with ``effect`` (an offset or a slope) fitted."""
    data = _torque(truth_offset, truth_weight, 0.0) + RNG.normal(0.0, NOISE, ANGLE.size)
    before, without = _fit(data, 0.0, effect)
    after, result = _fit(data, declared, effect)
    err_before, err_after = without.fun, result.fun
    named = SimpleNamespace(name=f"torque_{effect}", fittable=True)
    weight = SimpleNamespace(name="payload_gravity", fittable=False)
    base = Base(
        err_before,
        float(np.sqrt(np.mean(err_before**2))),
        aic(err_before, 1),
        NOISE,
        [named],
        [before],
    )
    step = Step(
        added=[weight],
        params=[after, np.array([declared])],
        err=err_after,
        rmse=float(np.sqrt(np.mean(err_after**2))),
        aic=aic(err_after, 1),
        gain=0.0,
        judged=(base.rmse, 0.0, NOISE),
        result=result,
        meaningful=True,
        joint=True,
    )
    return stood_in(step, base)


def test_an_offset_that_took_the_weight_gives_it_back() -> None:
    assert _case(WEIGHT, "offset")


def test_not_where_the_weight_makes_the_fit_worse() -> None:
    # no weight on the arm (a shuttle that left it): what is named refitted beside the
    # declared weight fits the cos(angle) shape worse than the noise allows
    assert not _case(0.0, "offset", truth_offset=0.0)
    assert not _case(0.0, "slope", truth_offset=0.0)


def test_not_where_nothing_named_had_taken_its_place() -> None:
    # a declared torque too small to move what is named (a tenth of the noise): alike, and
    # the offset stays inside its interval
    assert not _case(0.0, "offset", declared=NOISE / 10)
