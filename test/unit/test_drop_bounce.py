"""A rebound read off the load cell (drop_bounce) and what the candidates make of it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.drop import (
    DropProblem,
    load_drop_nominal,
    load_drop_trial,
)
from transparency_ros.analysis.discrepancy.drop_bounce import Bounces, shuttle_bounces
from transparency_ros.analysis.discrepancy.drop_effects import (
    DropEffect,
    HubArmCompliance,
    ShownRestitution,
)
from transparency_ros.analysis.discrepancy.drop_library import drop_library
from transparency_ros.analysis.discrepancy.drop_trials import DropTrial
from transparency_ros.analysis.discrepancy.revisit import rivals_again
from transparency_ros.analysis.discrepancy.steps import Base, Step, null_inside
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


def _given(cand: DropEffect, params: list[np.ndarray], own: np.ndarray, rmse: float) -> Step:
    """A step of ``cand`` with its fit given (``own``), removing 90 % of the error to ``rmse``."""
    return Step(
        added=[cand],
        params=[*params, own],
        err=np.full(1000, rmse),
        rmse=rmse,
        aic=1000 * np.log(rmse**2),
        gain=0.9,
        judged=(2e-3, rmse, 1e-4),
        result=None,
        meaningful=cand.meaningful(own),  # as Discoverer._step has it
    )


def _declared_after(
    rebound_fit: tuple[float, float],
    spring_fit: tuple[float, float],
    ratio: float,
    refused: dict[int, tuple[np.ndarray, bool]] | None = None,
) -> list[tuple[str, list[str]]]:
    """What the declared stage names from a shown rebound fitted ``rebound_fit`` (e, log10 of
    the contact's stiffness) whose rival, the hub spring, fitted ``spring_fit`` (log10 of its
    stiffness, damping ratio) with ``ratio`` times its held-out RMSE; the rebound fitted on
    top of the spring has its coefficient's interval away from 0. The fits are given: what
    is tested is the rule that picks between them and what the loop does with its pick
    (``refused``: filled with the loop's record of the shown fits it refused)."""
    spring = HubArmCompliance(loaded_inertia_kgm2=0.01)
    shown = ShownRestitution(Bounces(struck_again=8, left=8, of=8, pause_s=0.008), rival=spring)
    fitted = {id(shown): np.array(rebound_fit), id(spring): np.array(spring_fit)}

    def single(
        effects: list[object], params: list[np.ndarray], cand: object, base: Base, **_: object
    ) -> Step:
        rmse = 1e-3 * (ratio if cand is spring else 1.0) * (0.9 if effects else 1.0)
        return _given(cand, params, fitted[id(cand)], rmse)

    loop = Discoverer.__new__(Discoverer)
    loop.problem = SimpleNamespace(candidates=lambda: [shown])
    loop.progress = lambda _t: None
    loop._refused = {}
    loop._single = single  # type: ignore[method-assign]
    loop._finding = lambda cand, step, *_a: SimpleNamespace(  # type: ignore[method-assign]
        effect=cand.name, alternatives=step.alternatives, evidence=""
    )
    report = SimpleNamespace(findings=[])
    loop._declared(report, [], [], np.full(1000, 2e-3), 1e-4)  # type: ignore[arg-type]
    if refused is not None:  # each refused step's fit, and whether its interval held the null
        refused |= {k: (s.new()[-1][1], null_inside(s)) for k, s in loop._refused.items()}
    return [(f.effect, f.alternatives) for f in report.findings]


def test_a_shown_bounce_a_ringing_hub_spring_explains_alike_is_named_as_the_spring() -> None:
    """The load cell shows the shuttle thrown off. Where a spring between hub and arm that
    rings (damping ratio below 0.1) explains it within 10 % of a rebound that needed a soft
    contact (below 10^5.9 N/m), the spring is named, the rebound given as the alternative and
    tried again on top of it; otherwise the rebound is named as before."""
    ring = _declared_after((0.9, 5.2), (3.3, 0.03), 1.09)
    assert [name for name, _ in ring] == ["structural_compliance", "restitution"]
    assert "a rebound off a soft contact (e 0.90, 1.58e+05 N/m" in ring[0][1][0]
    # a 180 Hz ring imitated by a rebound off 10^5.87 N/m (zoo_12362): the spring
    ring = _declared_after((0.9, 5.87), (3.87, 0.024), 0.98)
    assert ring[0][0] == "structural_compliance"
    # a stiff contact's rebound, a spring that does not ring (a backlash's throw), a spring
    # that explains it less well: the rebound
    for rebound, spring, ratio in (
        ((0.6, 6.4), (3.3, 0.03), 1.0),
        ((0.6, 5.95), (3.8, 0.03), 1.0),
        ((0.6, 5.2), (3.3, 0.2), 0.99),
        ((0.9, 5.2), (3.3, 0.03), 1.11),
    ):
        assert [name for name, _ in _declared_after(rebound, spring, ratio)] == ["restitution"]


def test_the_spring_in_a_shown_rebounds_place_carries_the_rebounds_own_fit() -> None:
    """Where the shown rebound yields to the ringing spring, the spring's step carries the
    rebound's step (its fitted values go into the finding as the alternative, findings.
    alike_fits); where it does not yield (a damped spring), there is no such step."""
    spring = HubArmCompliance(loaded_inertia_kgm2=0.01)
    shown = ShownRestitution(Bounces(struck_again=8, left=8, of=8, pause_s=0.008), rival=spring)
    own = _given(shown, [], np.array([0.9, 5.2]), 1e-3)
    base = Base(np.full(1000, 2e-3), 2e-3, 0.0, 1e-4, [], [])
    for damping, yields in ((0.03, True), (0.3, False)):
        loop = Discoverer.__new__(Discoverer)
        loop._single = lambda e, p, c, b, d=damping, **_: _given(  # type: ignore[method-assign]
            c, p, np.array([3.3, d]), 1.05e-3
        )
        other = loop._rival_instead([], [], shown, own, base)
        if yields:
            assert other is not None and other.added == [spring] and other.shown
            assert other.alike == [own]
        else:
            assert other is None


def test_a_shown_bounce_fitted_as_a_stiff_contacts_chatter_names_no_rebound() -> None:
    """A light arm springs back and throws the shuttle off a stiff contact for a few ms: the
    load cell shows it strike again, and the rebound fitted to it is small. Below e 0.17 it
    is not named, whatever it gains; from there on it is, as before."""
    refused: dict[int, tuple[np.ndarray, bool]] = {}
    assert _declared_after((0.10, 6.4), (3.3, 0.2), 1.0, refused) == []
    # (the loop keeps the refused fit for the report's note on the bounce)
    assert [(float(p[0]), null) for p, null in refused.values()] == [(0.10, False)]
    assert _declared_after((0.16, 6.4), (3.3, 0.2), 1.0) == []
    assert [name for name, _ in _declared_after((0.25, 6.4), (3.3, 0.2), 1.0)] == ["restitution"]
    # in the standard rule too (a pair with a searched effect): the same size is refused
    shown = ShownRestitution(Bounces(struck_again=8, left=8, of=8, pause_s=0.008))
    assert not shown.shows(np.array([0.1, 6.4])) and shown.shows(np.array([0.3, 6.4]))
    # the report's note says why no rebound was named
    assert "e 0.10, under 0.17" in shown.unnamed(np.array([0.1, 6.4]), False)
    assert "holds e = 0" in shown.unnamed(np.array([0.3, 6.4]), True)


def _final_loop(shown: ShownRestitution, searched: object, single: object) -> Discoverer:
    """A loop (stubbed: ``single`` gives each fit) whose search ended having named
    ``searched``, for rivals_again on its final model."""
    loop = Discoverer.__new__(Discoverer)
    loop.problem = SimpleNamespace(
        candidates=lambda: [shown], error=lambda *_a: np.full(1000, 2e-3)
    )
    loop.min_improvement = 0.75
    loop.progress = lambda _t: None
    loop._refused = {}
    loop._searched = {id(searched)}
    loop._single = single  # type: ignore[method-assign]
    loop._finding = lambda cand, step, *_a: SimpleNamespace(  # type: ignore[method-assign]
        effect=cand.name, alternatives=step.alternatives, evidence=""
    )
    return loop


def _decided_again(
    named: str, ratio: float, on_top: float
) -> tuple[list[str], list[str], list[np.ndarray]]:
    """rivals_again on a final model of a sensor delay and ``named`` (the hub spring or the
    shown rebound), the spring fitted on it ``ratio`` times the rebound's held-out RMSE and
    a rebound on top of the spring fitted at e ``on_top``: (the findings' effects, the
    model's effects, its parameters)."""
    spring = HubArmCompliance(loaded_inertia_kgm2=0.01)
    shown = ShownRestitution(Bounces(struck_again=8, left=8, of=8, pause_s=0.008), rival=spring)
    delay = SimpleNamespace(name="sensor_delay", fittable=True)
    fitted = {id(shown): np.array([0.8, 5.5]), id(spring): np.array([4.1, 0.04])}

    def single(
        effects: list[object], params: list[np.ndarray], cand: object, base: Base, **_: object
    ) -> Step:
        assert effects[0] is delay  # the final model without the one to decide again
        rmse = 1e-3 * (ratio if cand is spring else 1.0)
        # on top of the spring, what is left of the rebound
        own = np.array([on_top, 6.3]) if spring in effects else fitted[id(cand)]
        return _given(cand, params, own, rmse)

    loop = _final_loop(shown, delay, single)
    first = spring if named == "structural_compliance" else shown
    report = SimpleNamespace(
        nominal={},
        split={},
        findings=[SimpleNamespace(effect=first.name), SimpleNamespace(effect="sensor_delay")],
    )
    effects, params = rivals_again(
        loop,
        report,  # type: ignore[arg-type]
        [first, delay],
        [fitted[id(first)], np.array([1.6e-3])],
        1e-4,
    )
    return [f.effect for f in report.findings], [e.name for e in effects], params


@pytest.mark.parametrize(
    ("ratio", "on_top", "named"),
    [
        (1.26, 0.1, "restitution"),
        (1.01, 0.1, "structural_compliance"),
        (1.01, 0.5, "structural_compliance"),
    ],
)
def test_a_rivalry_is_decided_again_on_the_model_the_search_ended_with(
    ratio: float, on_top: float, named: str
) -> None:
    """A shown bounce yielded to a ringing hub spring while a sensor delay, found later, was
    missing. On the final model (the delay in) the two are fitted again: where the spring
    now explains the held-out recordings 1.26 times worse than the rebound (zoo_10202), the
    rebound replaces it, and the delay keeps its finding; where it is still alike, the spring
    stays as named, and so it does where a rebound would now be named on top of it (e 0.5:
    what is named on top of a spring was the search's to decide)."""
    findings, effects, params = _decided_again("structural_compliance", ratio, on_top)
    assert findings == (
        ["sensor_delay", named] if named == "restitution" else [named, "sensor_delay"]
    )
    assert effects == findings and len(params) == len(effects)


@pytest.mark.parametrize(
    ("ratio", "on_top", "named"),
    [
        (0.96, 0.36, ["structural_compliance", "restitution"]),
        (0.96, 0.10, ["structural_compliance"]),
        (1.26, 0.36, ["restitution"]),
    ],
)
def test_a_rebound_named_gives_way_to_the_spring_and_comes_back_on_top_of_it(
    ratio: float, on_top: float, named: list[str]
) -> None:
    """A shown bounce was named as a rebound before the rail friction was found (zoo_10665).
    On the final model the ringing hub spring explains the held-out recordings better (0.96
    times the rebound's RMSE): the spring is named, and the rebound the load cell shows again
    on top of it (e 0.36), not where what is left of it is a stiff contact's chatter (e 0.10);
    where the spring explains them worse, the rebound stays alone."""
    findings, effects, params = _decided_again("restitution", ratio, on_top)
    if named == ["restitution"]:
        assert findings == ["restitution", "sensor_delay"]
    else:
        assert findings == ["sensor_delay", *named]
    assert effects == findings and len(params) == len(effects)


def _both_decided_again(
    on_final: tuple[float, float], spring_gain: float
) -> tuple[list[str], list[str], list[np.ndarray]]:
    """rivals_again on a final model of the hub spring (named in a shown rebound's place), a
    rebound of e 0.24 named on top of it and a drift found after both; on that model without
    the two the rebound is fitted at ``on_final`` (e, log10 of the contact's stiffness), the
    spring alone explains it as well and rings, and the spring fitted on top of the rebound
    removes ``spring_gain`` of what is left: (the findings' effects, the model's effects, its
    parameters)."""
    spring = HubArmCompliance(loaded_inertia_kgm2=0.01)
    shown = ShownRestitution(Bounces(struck_again=8, left=8, of=8, pause_s=0.008), rival=spring)
    drift = SimpleNamespace(name="parameter_drift", fittable=True)

    def single(
        effects: list[object], params: list[np.ndarray], cand: object, base: Base, **_: object
    ) -> Step:
        assert effects[0] is drift  # the final model without the two
        if cand is spring and shown in effects:  # the spring on top of the rebound
            left = 1e-3 * (1 - spring_gain) + 1e-5
            step = _given(spring, params, np.array([4.7, 0.03]), left)
            return replace(step, gain=spring_gain, judged=(1e-3, left, 1e-4))
        own = np.array(on_final) if cand is shown else np.array([3.9, 0.03])
        return _given(cand, params, own, 1e-3)

    loop = _final_loop(shown, drift, single)
    named = [spring, shown, drift]
    report = SimpleNamespace(
        nominal={}, split={}, findings=[SimpleNamespace(effect=e.name) for e in named]
    )
    effects, params = rivals_again(
        loop,
        report,  # type: ignore[arg-type]
        named,
        [np.array([4.7, 0.02]), np.array([0.24, 6.9]), np.array([1.4, 1.0, 1.0])],
        1e-4,
    )
    return [f.effect for f in report.findings], [e.name for e in effects], params


@pytest.mark.parametrize(
    ("on_final", "spring_gain", "named"),
    [
        ((0.72, 6.5), 0.0, ["parameter_drift", "restitution"]),
        ((0.72, 5.8), 0.0, ["structural_compliance", "restitution", "parameter_drift"]),
        ((0.72, 6.5), 0.9, ["structural_compliance", "restitution", "parameter_drift"]),
    ],
)
def test_a_spring_named_for_a_rebound_is_given_up_where_the_rebound_explains_it_at_the_end(
    on_final: tuple[float, float], spring_gain: float, named: list[str]
) -> None:
    """A shown rebound gave way to a ringing hub spring (it needed a soft contact), the
    rebound came on top of the spring at e 0.24, and a drift was found after (zoo_13345). On
    the final model without the two, the rebound alone is e 0.72 off a stiff contact
    (10^6.5 N/m): it no longer imitates a ring, and where the spring fitted on top of it
    removes nothing, the spring is given up, the rebound keeping its refitted value. Where
    the rebound still needs a soft contact (10^5.8, a true ring: zoo_12409), or the spring
    on top of it removes 90 % of what is left, both stay as named."""
    findings, effects, params = _both_decided_again(on_final, spring_gain)
    assert findings == named and effects == named and len(params) == len(named)
    if "structural_compliance" not in named:
        assert params[-1].tolist() == [0.72, 6.5]
