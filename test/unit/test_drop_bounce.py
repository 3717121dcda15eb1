"""A rebound read off the load cell (drop_bounce) and what the candidates make of it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.drop import (
    DropProblem,
    load_drop_nominal,
    load_drop_trial,
)
from transparency_ros.analysis.discrepancy.drop_bounce import Bounces, shuttle_bounces
from transparency_ros.analysis.discrepancy.drop_effects import (
    DropEffect,
    ShownRestitution,
    drop_library,
)
from transparency_ros.analysis.discrepancy.drop_trials import DropTrial
from transparency_ros.bag.reader import find_bags
from transparency_ros.synth.drop_campaign import write_drop_campaign


def _trials(tmp_path: Path) -> list[DropTrial]:
    # the shuttle's weight on the arm: the load cell reads it while the shuttle rides
    out = write_drop_campaign(tmp_path / "c", 2, hidden=["payload_gravity"], actuator="EC60")
    return [load_drop_trial(b) for b in find_bags([str(out / "bags")])]


def _apart(trial: DropTrial, after_s: float, for_s: float | None) -> DropTrial:
    """``trial`` with its load cell at the fall's level (nothing on it) from ``after_s`` after
    contact, for ``for_s`` (None: to the end)."""
    force = trial.force.copy()
    t = trial.t_h - trial.contact_s
    fall = (t > -0.02) & (t < -0.001)
    span = (t >= after_s) & (True if for_s is None else t < after_s + for_s)
    force[span] = np.median(force[fall])
    return replace(trial, force=force)


def _rebounds(bounces: Bounces) -> list[DropEffect]:
    library = drop_library(0.54, 0.03, 1e-3, 1e-3, bounces=bounces)
    return [c for c in library if c.name == "restitution"]


def _rebound(trials: list[DropTrial]) -> list[str]:
    return [type(c).__name__ for c in _rebounds(shuttle_bounces(trials))]


def test_a_rebound_is_read_off_the_load_cell(tmp_path: Path) -> None:
    """The shuttle riding the arm keeps the load cell at its weight: no rebound, none searched
    for. A 10 ms pause between two strikes in every trial is a rebound shown (named, its
    coefficient fitted); one low reading is noise; a shuttle that leaves the arm and is not
    back before the recording ends may have rebounded (searched for, not named as shown)."""
    trials = _trials(tmp_path)
    riding = shuttle_bounces(trials)
    assert (riding.left, riding.struck_again, riding.of) == (0, 0, len(trials))
    assert not riding.possible and _rebound(trials) == []

    bounced = [_apart(t, 0.002, 0.010) for t in trials]
    seen = shuttle_bounces(bounced)
    assert seen.shown and seen.struck_again == len(trials)
    assert seen.pause_s == pytest.approx(0.010, abs=2e-4)
    assert _rebound(bounced) == ["ShownRestitution"]
    (shown,) = _rebounds(seen)
    assert isinstance(shown, ShownRestitution) and shown.declared and shown.fittable
    assert f"strike it again in {len(trials)} of {len(trials)} trials" in shown.describe()

    glitch = [_apart(t, 0.002, 0.0001) for t in trials]
    assert shuttle_bounces(glitch).left == 0

    gone = [_apart(t, 0.002, None) for t in trials]
    away = shuttle_bounces(gone)
    assert away.possible and not away.shown
    assert _rebound(gone) == ["DropRestitution"]
    # one trial alone does not show it where there are more
    one = [bounced[0], *trials[1:]]
    assert not shuttle_bounces(one).shown


def test_without_a_reading_the_rebound_is_searched_for() -> None:
    """A library built without the load cell's reading searches for a rebound, as before."""
    library = drop_library(0.54, 0.03, 1e-3, 1e-3)
    assert [type(c).__name__ for c in library if c.name == "restitution"] == ["DropRestitution"]


def test_a_shown_rebound_is_in_the_problems_candidates(tmp_path: Path) -> None:
    trials = [_apart(t, 0.002, 0.010) for t in _trials(tmp_path)]
    problem = DropProblem(trials, load_drop_nominal(None, trials))
    assert [type(c).__name__ for c in problem.candidates() if c.name == "restitution"] == [
        "ShownRestitution"
    ]
