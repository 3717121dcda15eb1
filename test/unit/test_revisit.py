"""Decisions the loop takes again once its search has ended (revisit): an effect named before
the one that really explains the recordings is tried again on the final model."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.findings import Report
from transparency_ros.analysis.discrepancy.revisit import still_needed
from transparency_ros.analysis.discrepancy.steps import Base, Step


def _effect(name: str, **flags: bool) -> SimpleNamespace:
    # nothing to refit among the others (refit returns them as they are)
    return SimpleNamespace(name=name, fittable=False, meaningful=lambda _p: True, **flags)


def _loop(gains: dict[str, float], searched: tuple[object, ...]) -> Discoverer:
    """A loop whose candidate, added to the final model without it, removes ``gains[name]``
    of the error left (2 mrad, floor 0.1 mrad), and whose search named ``searched`` alone."""
    loop = Discoverer.__new__(Discoverer)
    loop.problem = SimpleNamespace(error=lambda *_a: np.full(1000, 2e-3))
    loop.min_improvement = 0.75
    loop.progress = lambda _t: None
    loop._searched = {id(p) for p in searched}

    def single(effects: list[object], params: list[np.ndarray], cand: object, base: Base) -> Step:
        after = base.rmse - gains[cand.name] * (base.rmse - base.floor)
        return Step(
            added=[cand],
            params=[*params, np.zeros(1)],
            err=np.full(1000, after),
            rmse=after,
            aic=1000 * np.log(after**2) + 2,
            gain=gains[cand.name],
            judged=(base.rmse, after, base.floor),
            result=None,
            meaningful=True,
        )

    loop._single = single  # type: ignore[method-assign]
    return loop


def _report(effects: list[SimpleNamespace]) -> Report:
    report = Report({}, {})
    report.findings = [SimpleNamespace(effect=e.name) for e in effects]  # type: ignore[misc]
    return report


def test_an_effect_the_one_found_after_it_explains_is_dropped() -> None:
    """A spring named first stood in for a sensor delay found after it (zoo_10279): on the
    final model it removes a tenth of what is left without it and is dropped, with its
    finding and a note; the delay, which still explains most of what is left without it,
    stays; the declared weight is not tried."""
    weight = _effect("payload_gravity")
    spring, delay = _effect("structural_compliance"), _effect("sensor_delay")
    effects = [weight, spring, delay]
    report = _report(effects)
    loop = _loop({"structural_compliance": 0.1, "sensor_delay": 0.9}, (spring, delay))
    kept, params = still_needed(loop, report, effects, [np.zeros(1)] * 3, 1e-4)
    assert kept == [weight, delay] and len(params) == 2
    assert [f.effect for f in report.findings] == ["payload_gravity", "sensor_delay"]
    assert any("dropped structural_compliance" in n for n in report.notes)


def test_what_still_explains_enough_and_what_the_search_did_not_name_alone_stay() -> None:
    """Effects that still name on the final model stay; those the search did not name alone
    (two named together, neither explaining it alone; declared; standing for a shown
    effect) are never tried."""
    first, second = _effect("backlash"), _effect("sensor_delay")
    offset = _effect("torque_offset")
    effects = [offset, first, second]
    report = _report(effects)
    loop = _loop({"backlash": 0.2, "sensor_delay": 0.2, "torque_offset": 0.0}, ())
    kept, _ = still_needed(loop, report, effects, [np.zeros(1)] * 3, 1e-4)
    assert kept == effects and not report.notes
    loop = _loop({"backlash": 0.8, "sensor_delay": 0.9, "torque_offset": 0.0}, (first, second))
    kept, _ = still_needed(loop, report, effects, [np.zeros(1)] * 3, 1e-4)
    assert kept == effects and len(report.findings) == 3
