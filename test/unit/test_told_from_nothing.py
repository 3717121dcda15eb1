"""The rule that names nothing whose 95 % interval holds its value of no effect, read once
more on the final model (revisit.told_from_nothing): zoo_12711 named an offset in a pair
beside a b_v drift, where it held the shuttle's weight; once the weight was named, the offset
was refitted to 0.0001 N m (95 % -0.0004 to 0.0006) and was still reported."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.findings import Finding, Report
from transparency_ros.analysis.discrepancy.revisit import told_from_nothing

LEFT = 1e-3  # the held-out error the final model leaves [rad]


def _effect(name: str, params: tuple[str, ...], null: tuple[float, ...], **flags: Any) -> Any:
    kinds = {"declared": False, "shown": False} | flags
    return SimpleNamespace(name=name, param_names=params, null=null, fittable=True, **kinds)


def _finding(effect: Any, values: list[float], intervals: list[tuple[float, float]]) -> Finding:
    return Finding(
        effect=effect.name,
        parameters=dict(zip(effect.param_names, values, strict=True)),
        confidence_interval=dict(zip(effect.param_names, intervals, strict=True)),
        where={},
        evidence="",
        heldout_rmse_before=2 * LEFT,
        heldout_rmse_after=LEFT,
    )


def _run(
    named: list[tuple[Any, list[float], list[tuple[float, float]]]], needed: float = 1.0
) -> tuple[list[str], Report]:
    """The check on a final model of ``named`` (effect, values, intervals); the weight (not
    fitted) first. Without an effect whose name is "needed", the held-out error is ``needed``
    times what it is with it. Returns the names kept and the report."""
    weight = SimpleNamespace(name="payload_gravity", param_names=(), fittable=False)
    effects = [weight, *(e for e, _v, _c in named)]
    params = [np.array([0.53]), *(np.array(v) for _e, v, _c in named)]

    def error(model: list[Any], _params: list[np.ndarray], _held: bool) -> np.ndarray:
        missing = not any(e.name == "needed" for e in model)
        return np.full(500, LEFT * (needed if missing else 1.0))

    loop = Discoverer.__new__(Discoverer)
    loop.problem = SimpleNamespace(error=error)  # type: ignore[assignment]
    loop.progress = lambda _t: None
    report = Report({}, {}, findings=[
        _finding(SimpleNamespace(name="payload_gravity", param_names=()), [], []),
        *(_finding(e, v, c) for e, v, c in named),
    ])  # fmt: skip
    # (every effect's fit held by itself: nothing to refit among the others)
    for e in effects:
        e.fittable = e.fittable and e.name != "payload_gravity"
    kept, _params, held = told_from_nothing(loop, report, effects, params, error(effects, [], True))
    assert held.size == 500
    return [e.name for e in kept], report


def test_an_effect_refitted_to_nothing_is_dropped_with_a_note() -> None:
    offset = _effect("torque_offset", ("offset_nm",), (0.0,))
    drift = _effect("parameter_drift", ("viscous_scale",), (1.0,))
    kept, report = _run([(drift, [1.66], [(1.33, 1.99)]), (offset, [1e-4], [(-4e-4, 6e-4)])])
    assert kept == ["payload_gravity", "parameter_drift"]
    assert [f.effect for f in report.findings] == ["payload_gravity", "parameter_drift"]
    assert any("dropped torque_offset" in n and "-0.0004" in n for n in report.notes)


def test_an_effect_told_from_nothing_stays() -> None:
    offset = _effect("torque_offset", ("offset_nm",), (0.0,))
    kept, report = _run([(offset, [4e-3], [(3e-3, 5e-3)])])
    assert kept == ["payload_gravity", "torque_offset"] and not report.notes


def test_a_parameter_whose_null_is_any_value_does_not_keep_it() -> None:
    # a cogging's phase (null NaN: any phase is no wave) does not tell it from nothing
    cogging = _effect("cogging", ("amplitude_nm", "phase_rad"), (0.0, math.nan))
    kept, _ = _run([(cogging, [0.002, 1.0], [(-0.001, 0.005), (0.5, 1.5)])])
    assert kept == ["payload_gravity"]


def test_one_the_held_out_data_still_need_stays() -> None:
    # without it the held-out error is 1.2 times higher: more than ALIKE (1.05)
    needed = _effect("needed", ("offset_nm",), (0.0,))
    kept, _ = _run([(needed, [1e-4], [(-4e-4, 6e-4)])], needed=1.2)
    assert kept == ["payload_gravity", "needed"]
    kept, _ = _run([(needed, [1e-4], [(-4e-4, 6e-4)])], needed=1.04)
    assert kept == ["payload_gravity"]


def test_effects_the_recording_declares_or_shows_are_not_judged_by_their_fit() -> None:
    rebound = _effect("restitution", ("coefficient",), (0.0,), shown=True)
    declared = _effect("quantization", ("step_rad",), (0.0,), declared=True)
    kept, _ = _run([(rebound, [0.3], [(-0.2, 0.8)]), (declared, [1e-3], [(-1e-3, 3e-3)])])
    assert kept == ["payload_gravity", "restitution", "quantization"]
