"""Explanations the recordings cannot tell apart are reported with their own fitted values and,
where the recordings say why, with what would tell them apart (findings.alike_fits,
DropProblem.told_apart)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from test.unit.test_discrepancy import _step as discrepancy_step
from transparency_ros.analysis.discrepancy.drop import (
    DropProblem,
    load_drop_nominal,
    load_drop_trial,
)
from transparency_ros.analysis.discrepancy.drop_effects import (
    DeclaredWeight,
    DropDrift,
    DropOffset,
    DropRestitution,
    HubArmCompliance,
)
from transparency_ros.analysis.discrepancy.findings import alike_fits, alike_text, finding
from transparency_ros.analysis.discrepancy.steps import Base, Step, choose
from transparency_ros.bag.reader import find_bags
from transparency_ros.core import strict_json
from transparency_ros.synth.drop_campaign import write_drop_campaign


def _step(effect: object, p: list[float], rmse: float) -> Step:
    """A single added effect's step, its parameters set from a joint fit (no intervals)."""
    return replace(discrepancy_step(effect, p, rmse, 1e-4), joint=True)


class _Problem:
    """What finding() asks of a problem, with a told_apart that says which pair it saw."""

    def __init__(self) -> None:
        self.asked: list[tuple[list[str], list[str]]] = []

    def told_apart(self, named: list[Any], other: list[Any]) -> str:
        self.asked.append(([e.name for e in named], [e.name for e in other]))
        return "a trial that turns back tells them apart"

    def phases(self) -> dict[str, np.ndarray]:
        return {"deflection": np.ones(10_000, dtype=bool)}

    def segments(self) -> tuple[np.ndarray, list[tuple[str, float, float]]]:
        return np.zeros(10_000, dtype=np.int64), [("t0", 0.0, 1.0)]


def test_an_alternative_is_reported_with_its_values_its_fit_and_what_tells_it_apart() -> None:
    """The offset named over a Coulomb drift that fits alike: the finding lists the drift's own
    fitted scale, its held-out RMSE against the offset's and the problem's reason; the
    evidence says them; the JSON is strict."""
    coulomb, offset = DropDrift((False, False, True)), DropOffset(0.03)
    named = choose(
        [_step(coulomb, [0.63], 1.00e-3), _step(offset, [-0.094], 1.01e-3)],
        lambda _e, _p: False,
    )
    assert named is not None and named.added == [offset]
    assert [s.added for s in named.alike] == [[coulomb]]
    problem = _Problem()
    alike = alike_fits(problem, named)
    assert problem.asked == [(["torque_offset"], ["parameter_drift"])]
    assert alike == [
        {
            "effect": "parameter_drift",
            "parameters": {
                "coulomb_scale": pytest.approx(0.63),
                "reflected_inertia_scale": 1.0,
                "viscous_scale": 1.0,
            },
            "heldout_rmse_ratio": pytest.approx(1.00 / 1.01),
            "told_apart_by": "a trial that turns back tells them apart",
        }
    ]
    base = Base(np.full(10_000, 5e-3), 5e-3, 0.0, 1e-4, [], [])
    f = finding(problem, offset, named, base, before=5e-3, after=1.01e-3)
    assert f.alternatives == ["parameter_drift"] and f.alike == alike
    assert "explained alike by parameter_drift (coulomb_scale 0.63" in f.evidence
    assert f.evidence.endswith("times this): a trial that turns back tells them apart")
    assert '"told_apart_by": "a trial that turns back' in strict_json.dumps(vars(f))


def test_without_fits_the_alternatives_are_named_and_without_a_reason_none_is_given() -> None:
    assert alike_text([], ["parameter_drift"]) == "; explained alike by parameter_drift"
    assert alike_text([], []) == ""
    text = alike_text(
        [
            {
                "effect": "torque_offset",
                "parameters": {"offset_nm": 0.05},
                "heldout_rmse_ratio": 1.02,
                "told_apart_by": None,
            }
        ],
        ["torque_offset"],
    )
    assert text == (
        "; explained alike by torque_offset (offset_nm 0.05; held-out RMSE 1.020 times this)"
    )


def _problem(out: Path) -> DropProblem:
    trials = [load_drop_trial(b) for b in find_bags([str(out / "bags")])]
    return DropProblem(trials, load_drop_nominal(None, trials))


def test_a_drop_test_says_an_offset_and_a_coulomb_drift_are_told_apart_by_an_arm_turning_back(
    tmp_path: Path,
) -> None:
    """An arm that turned one way in every trial: a constant torque and a Coulomb torque act
    alike, and the reason is given for that pair only. Once one trial's arm comes back from
    its farthest turn by ten counts, none is."""
    out = write_drop_campaign(tmp_path / "c", 3, hidden=["payload_gravity"], actuator="U10GB")
    problem = _problem(out)
    offset, coulomb = DropOffset(0.03), DropDrift((False, False, True))
    told = problem.told_apart([offset], [coulomb])
    n = len(problem.fit_trials) + len(problem.held_trials)
    assert told.startswith(f"the arm turned one way after contact in all {n} trials")
    assert problem.told_apart([coulomb], [offset]) == told
    assert problem.told_apart([offset], [DropDrift()]) == ""  # a drift of all three terms
    assert problem.told_apart([offset], [DeclaredWeight()]) == ""

    # halfway through its motion after contact, one trial's arm comes back by ten counts
    trial = problem.held_trials[0]
    after = np.flatnonzero(trial.t_q > trial.contact_s)
    q = trial.q.copy()
    q[after[after.size // 2] :] += 10 * max(problem.encoder_count, 1e-4)
    turned = replace(trial, q=q)
    trials = [*problem.fit_trials, turned, *problem.held_trials[1:]]
    again = DropProblem(trials, load_drop_nominal(None, trials))
    assert again.told_apart([offset], [coulomb]) == ""


def test_a_drop_test_says_a_rebound_and_a_hub_spring_are_told_apart_by_a_tap_on_a_light_arm(
    tmp_path: Path,
) -> None:
    """A rebound off the contact and a spring between hub and arm act alike on the motor where
    the arm is light against the shuttle, and the reason says how light; with an arm as heavy
    as the shuttle at its tip, no reason is given."""
    out = write_drop_campaign(tmp_path / "c", 4, hidden=["payload_gravity"], actuator="EC60")
    problem = _problem(out)
    spring, rebound = HubArmCompliance(0.01), DropRestitution()
    told = problem.told_apart([spring], [rebound])
    assert told.startswith("the arm is light against the shuttle (its inertia 0.")
    assert "a tap on the arm with the hub clamped tells them apart" in told
    assert problem.told_apart([rebound], [spring]) == told
    assert problem.told_apart([spring], [DropOffset(0.03)]) == ""
    trials = [
        replace(t, arm_inertia_kgm2=t.mass_kg * t.arm_m**2)
        for t in (*problem.fit_trials, *problem.held_trials)
    ]
    heavy = DropProblem(trials, load_drop_nominal(None, trials))
    assert heavy.told_apart([spring], [rebound]) == ""
