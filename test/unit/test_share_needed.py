"""The share of the held-out error a candidate must remove to be named: one for every effect,
or the problem's own per candidate (a drop test's cogging and backlash, calibrated on the zoo:
benchmarks/share_calibration.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.drop import SHARE_NEEDED, DropProblem
from transparency_ros.analysis.discrepancy.steps import Base, Step


def _effect(name: str, declared: bool = False) -> SimpleNamespace:
    return SimpleNamespace(name=name, declared=declared)


def _problem(shares: dict[str, float] | None) -> SimpleNamespace:
    problem = SimpleNamespace(min_improvement=0.75)
    if shares is not None:
        problem.share_needed = lambda e: shares.get(e.name, 0.75)
    return problem


def _step(added: list[SimpleNamespace], gain: float) -> tuple[Step, Base]:
    """A step removing ``gain`` of an error of 2 mrad above a floor of 0.1 mrad, by a margin
    of the information criterion that names it on every other count."""
    before, floor = 2e-3, 1e-4
    after = before - gain * (before - floor)
    base = Base(np.full(1000, before), before, 1000 * np.log(before**2), floor)
    return Step(
        added=added,
        params=[np.zeros(1)] * len(added),
        err=np.full(1000, after),
        rmse=after,
        aic=1000 * np.log(after**2) + 2,
        gain=gain,
        judged=(before, after, floor),
        result=None,
        meaningful=True,
    ), base


def test_a_candidate_is_judged_by_its_own_share_where_the_problem_has_one() -> None:
    """A cogging removing 0.70 of the error is named at its share of 0.65; a drift removing as
    much is not, at the share of every other effect (0.75)."""
    loop = Discoverer(_problem({"cogging": 0.65}))  # type: ignore[arg-type]
    assert loop._names(*_step([_effect("cogging")], 0.70))
    assert not loop._names(*_step([_effect("parameter_drift")], 0.70))
    assert loop._names(*_step([_effect("parameter_drift")], 0.80))
    assert not loop._names(*_step([_effect("cogging")], 0.60))


def test_a_pair_takes_the_stricter_share_and_a_declared_effect_none_of_its_own() -> None:
    loop = Discoverer(_problem({"cogging": 0.65, "backlash": 0.70}))  # type: ignore[arg-type]
    cogging, backlash = _effect("cogging"), _effect("backlash")
    weight, offset = _effect("payload_gravity", declared=True), _effect("torque_offset")
    assert loop.share_needed([cogging, backlash]) == 0.70
    assert loop.share_needed([cogging, offset]) == 0.75
    assert loop.share_needed([cogging, weight]) == 0.65  # (the searched one's)
    assert loop.share_needed([weight]) == 0.75


def test_a_share_given_to_the_loop_or_a_problem_without_its_own_is_one_for_all() -> None:
    """A share given to the loop (the calibration's logs are made under one) is used for every
    candidate; a problem without shares of its own (torque-driven) uses its min_improvement."""
    loop = Discoverer(_problem({"cogging": 0.65}), min_improvement=0.75)  # type: ignore[arg-type]
    assert loop.share_needed([_effect("cogging")]) == 0.75
    loop = Discoverer(_problem(None))  # type: ignore[arg-type]
    assert loop.share_needed([_effect("cogging")]) == 0.75


def test_the_drop_tests_shares_are_those_calibrated() -> None:
    """Cogging and backlash have shares of their own (below the uniform 0.75); every other
    drop-test candidate keeps the problem's min_improvement."""
    problem = DropProblem.__new__(DropProblem)
    problem.min_improvement = 0.75
    assert SHARE_NEEDED == {"cogging": 0.65, "backlash": 0.70}
    assert problem.share_needed(_effect("cogging")) == 0.65  # type: ignore[arg-type]
    assert problem.share_needed(_effect("backlash")) == 0.70  # type: ignore[arg-type]
    assert problem.share_needed(_effect("sensor_delay")) == 0.75  # type: ignore[arg-type]
