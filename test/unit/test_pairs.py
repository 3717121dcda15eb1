"""Pairs of candidates (discrepancy.pairs): fitted where no single effect explains what is left,
but not where one does at values it cannot mean (held at a bound of its range)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy import discover as discover_module
from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.pairs import out_of_range
from transparency_ros.analysis.discrepancy.steps import Base, Step

N = 1000
FLOOR = 1e-3
LEFT = 2e-3  # the held-out error left: 2x the floor in all, a phase at 5x


def _step(name: str, gain: float, *, meaningful: bool) -> Step:
    after = LEFT - gain * (LEFT - FLOOR)
    return Step(
        added=[SimpleNamespace(name=name, param_names=("scale",))],
        params=[np.array([5.0])],
        err=np.full(N, after),
        rmse=after,
        aic=N * np.log(after**2) + 2,
        gain=gain,
        judged=(LEFT, after, FLOOR),
        result=None,
        meaningful=meaningful,
    )


def _search(singles: dict[str, tuple[float, bool]], monkeypatch: pytest.MonkeyPatch) -> Any:
    """The loop's search on a model leaving 2 mrad (floor 1 mrad; a tenth of the held-out
    samples, phase 'fast', at 5x the floor) whose candidates remove
    ``singles[name] = (gain, meaningful)`` of it: (the report's notes, the pairs fitted)."""
    err = np.full(N, LEFT)
    err[: N // 10] = 5 * FLOOR
    fast = np.zeros(N, dtype=bool)
    fast[: N // 10] = True
    loop = Discoverer.__new__(Discoverer)
    loop.problem = SimpleNamespace(
        noise_floor=lambda: FLOOR,
        phases=lambda: {"fast": fast, "slow": ~fast},
        declared_stage=False,
        expected=lambda _e, _p: False,
    )
    loop.min_improvement = 0.5
    loop.progress = lambda _t: None
    loop._searched = set()
    made = {name: _step(name, gain, meaningful=m) for name, (gain, m) in singles.items()}
    loop._single = lambda _e, _p, cand, _b, start=None: made[cand.name]  # type: ignore[method-assign]
    fitted: list[str] = []

    def pairs(_loop: Discoverer, _e: Any, _p: Any, steps: list[Step], _b: Base) -> list[Step]:
        fitted.append("+".join(s.added[0].name for s in steps))
        return []

    monkeypatch.setattr(discover_module, "fitted_pairs", pairs)
    report = SimpleNamespace(notes=[])
    cands = [SimpleNamespace(name=name) for name in singles]
    loop._search(report, [], [], err, cands)  # type: ignore[arg-type]
    return report.notes, fitted


def test_no_pair_is_fitted_where_one_effect_explains_it_held_at_a_bound(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The real AK80-6 arm moved by hand (benchmarks/real_injection.py): a drift held at its
    inertia bound explained 133 % of what was left, and the pair fitted instead named an
    offset and a payload not there. The note says which effect and at what values."""
    notes, fitted = _search(
        {"drift": (1.3, False), "offset": (0.3, True), "payload": (0.2, True)}, monkeypatch
    )
    assert fitted == []
    assert len(notes) == 1
    assert "drift (scale 5) would remove 130%" in notes[0]
    assert "no pair" in notes[0]


def test_pairs_are_fitted_where_no_single_effect_explains_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The same, the drift held at its bound removing too little to be named anyway: the
    pairs are fitted, as where every single effect is meaningful."""
    for drift in ((0.3, False), (0.3, True)):
        notes, fitted = _search(
            {"drift": drift, "offset": (0.3, True), "payload": (0.2, True)}, monkeypatch
        )
        assert notes == []
        assert fitted == ["drift+offset+payload"]


def test_the_note_names_each_effect_with_its_values_and_share() -> None:
    note = out_of_range([_step("drift", 1.334, meaningful=False)])
    assert "drift (scale 5) would remove 133% of the held-out error" in note
