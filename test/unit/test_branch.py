"""A choice between fits alike made by an effect's yielding (a shown rebound to a hub spring in
the declared stage, a Coulomb drift to an offset in the search) is searched again the other way,
and the model that explains the held-out recordings better is reported (Discoverer.run,
branch.other_way, branch.other_branch). Stub loops: which step a choice makes, and which
report is kept."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.steps import ALIKE, Step

N = 1000
FLOOR = 1e-3
LEFT = 4e-3  # the held-out error each choice starts from


def _cand(name: str, yields: int = 0) -> Any:
    return SimpleNamespace(name=name, yields_to=yields, discrete_choices=0, shown=False)


def _step(cand: Any, after: float) -> Step:
    return Step(
        added=[cand],
        params=[np.array([1.0])],
        err=np.full(N, after),
        rmse=after,
        aic=N * np.log(after**2) + 2,
        gain=(LEFT - after) / (LEFT - FLOOR),
        judged=(LEFT, after, FLOOR),
        result=None,
        meaningful=True,
    )


def _loop(steps: dict[str, float], take: int | None = None) -> Discoverer:
    """A loop whose candidates leave ``steps[name]`` of the held-out error (RMSE) when
    added; ``take``: the choice made the other way."""
    loop = Discoverer.__new__(Discoverer)
    loop.problem = SimpleNamespace(
        noise_floor=lambda: FLOOR, declared_stage=False, expected=lambda _e, _p: False
    )
    loop.min_improvement = 0.5
    loop.progress = lambda _t: None
    loop._searched, loop._refused = set(), {}
    loop._ties, loop._tie, loop._take = 0, None, take
    made: dict[str, Step] = {}

    def single(_e: Any, _p: Any, cand: Any, _b: Any, **_k: Any) -> Step:
        made.setdefault(cand.name, _step(cand, steps[cand.name]))
        return made[cand.name]

    loop._single = single  # type: ignore[method-assign]
    loop._finding = lambda cand, *_a: SimpleNamespace(effect=cand.name, evidence="")  # type: ignore[method-assign]
    return loop


def _searched(loop: Discoverer, cands: list[Any]) -> list[str]:
    report = SimpleNamespace(findings=[], notes=[])
    loop._search(report, [], [], np.full(N, LEFT), cands)  # type: ignore[arg-type]
    return [f.effect for f in report.findings]


def test_the_search_takes_the_step_an_effect_yielded_where_told() -> None:
    # the drift explains it a little better, alike: the offset is named, the tie kept
    cands = [_cand("torque_offset"), _cand("parameter_drift", yields=1)]
    fits = {"torque_offset": 1.20e-3, "parameter_drift": 1.19e-3}
    loop = _loop(fits)
    assert _searched(loop, cands) == ["torque_offset"]
    assert loop._tie == (0, "parameter_drift")
    assert _searched(_loop(fits, take=0), cands) == ["parameter_drift"]
    # not alike (beyond ALIKE): no tie, whatever yields
    apart = {"torque_offset": 1.20e-3, "parameter_drift": 1.20e-3 / ALIKE / 1.01}
    loop = _loop(apart)
    assert _searched(loop, cands) == ["parameter_drift"]
    assert loop._tie is None
    # alike, neither yields: the information criterion chose, no tie
    loop = _loop(fits)
    assert _searched(loop, [_cand("torque_offset"), _cand("parameter_drift")]) == [
        "parameter_drift"
    ]
    assert loop._tie is None


def test_a_shown_effect_that_gave_way_to_its_rival_is_taken_where_told() -> None:
    rebound, spring = _cand("restitution", yields=1), _cand("structural_compliance")
    rebound.shown = True

    def added(take: int | None) -> tuple[list[str], Discoverer]:
        loop = _loop({"restitution": 1.2e-3, "structural_compliance": 1.2e-3}, take)

        def rival(effects: list[Any], _p: Any, _c: Any, _s: Any, base: Any) -> Step | None:
            # (none once the spring is in the model, as Discoverer._rival_instead)
            return None if spring in effects else loop._single([], [], spring, base)

        loop._rival_instead = rival  # type: ignore[method-assign]
        report = SimpleNamespace(findings=[], notes=[])
        loop._each_added(
            report,  # type: ignore[arg-type]
            ([], [], np.full(N, LEFT)),
            [rebound],
            FLOOR,
            lambda _s, _b: True,
        )
        return [f.effect for f in report.findings], loop

    named, loop = added(None)
    assert named == ["structural_compliance", "restitution"]  # (tried again on top of it)
    assert loop._tie == (0, "restitution")
    named, loop = added(0)
    assert named == ["restitution"]
    assert loop._tie is None


@pytest.mark.parametrize(
    ("branch_rmse", "branch_params", "kept"),
    [
        (1.0e-3, 2, "branch"),  # better beyond ALIKE and by the criterion
        (1.2e-3 / ALIKE * 1.01, 2, "first"),  # within ALIKE: alike, the first kept
        (0.9e-3, 1000, "first"),  # better, but not by the information criterion
    ],
)
def test_the_other_branch_is_reported_only_where_it_explains_better(
    branch_rmse: float, branch_params: int, kept: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    runs: list[int | None] = []
    wave = SimpleNamespace(name="cogging", periods=40)  # (a scan's choice kept in the effect)

    def run_once(self: Discoverer) -> tuple[Any, Any, Any]:
        runs.append(self._take)
        if self._take is None:
            self._tie = (3, "restitution")
            first = SimpleNamespace(name="first", notes=[], fitted=[(wave, np.ones(2))])
            return first, np.full(N, 1.2e-3), [np.ones(2)]
        wave.periods = 90  # the same candidate scanned again in the other search
        return (
            SimpleNamespace(name="branch", notes=[], fitted=[(wave, np.ones(2))]),
            np.full(N, branch_rmse),
            [np.ones(branch_params)],
        )

    monkeypatch.setattr(Discoverer, "_run_once", run_once)
    report = Discoverer(SimpleNamespace(min_improvement=0.5)).run()  # type: ignore[arg-type]
    assert runs == [None, 3]  # the branch made the kept choice the other way
    assert report.name == kept
    assert "taking restitution there instead" in report.notes[-1]
    assert ("not reported" in report.notes[-1]) == (kept == "first")
    assert report.fitted[0][0].periods == (40 if kept == "first" else 90)


def test_no_second_search_without_a_tie(monkeypatch: pytest.MonkeyPatch) -> None:
    runs: list[int | None] = []

    def run_once(self: Discoverer) -> tuple[Any, Any, Any]:
        runs.append(self._take)
        return SimpleNamespace(notes=[]), np.full(N, 1e-3), [np.ones(2)]

    monkeypatch.setattr(Discoverer, "_run_once", run_once)
    Discoverer(SimpleNamespace(min_improvement=0.5)).run()  # type: ignore[arg-type]
    assert runs == [None]
