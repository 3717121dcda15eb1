"""Pairs of candidates (discrepancy.pairs): fitted where no single effect explains what is left;
where one does only at values it cannot mean (held at a bound of its range), only pairs with
it (one beside it may bring it into its range; two without it stand in for it)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy import discover as discover_module
from transparency_ros.analysis.discrepancy import pairs as pairs_module
from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.pairs import fitted_pairs, out_of_range
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


def _loop(singles: dict[str, tuple[float, bool]]) -> Discoverer:
    """A loop on a model leaving 2 mrad (floor 1 mrad; a tenth of the held-out samples,
    phase 'fast', at 5x the floor) whose candidates remove ``singles[name] = (gain,
    meaningful)`` of it; its progress lines in ``loop.said``."""
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
    said: list[str] = []
    loop.progress = said.append
    loop.said = said  # type: ignore[attr-defined]
    loop._searched = set()
    made = {name: _step(name, gain, meaningful=m) for name, (gain, m) in singles.items()}
    loop._single = lambda _e, _p, cand, _b, start=None: made[cand.name]  # type: ignore[method-assign]
    return loop


def _search(singles: dict[str, tuple[float, bool]], monkeypatch: pytest.MonkeyPatch) -> Any:
    """The loop's search (nothing named, no pair naming): (the report's notes, the names of
    the singles the pairs were asked to keep to)."""
    err = np.full(N, LEFT)
    err[: N // 10] = 5 * FLOOR
    kept: list[list[str]] = []

    def pairs(
        _loop: Discoverer, _e: Any, _p: Any, _s: list[Step], _b: Base, *, beyond: list[Step]
    ) -> list[Step]:
        kept.append([s.added[0].name for s in beyond])
        return []

    monkeypatch.setattr(discover_module, "fitted_pairs", pairs)
    report = SimpleNamespace(notes=[])
    cands = [SimpleNamespace(name=name) for name in singles]
    _loop(singles)._search(report, [], [], err, cands)  # type: ignore[arg-type]
    return report.notes, kept


def test_pairs_keep_to_an_effect_that_explains_it_held_at_a_bound(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The real AK80-6 arm moved by hand (benchmarks/real_injection.py): a drift held at its
    inertia bound explained 133 % of what was left, and the pair fitted without it named an
    offset and a payload not there. The pairs keep to the drift; where none names, a note
    says which effect explained it and at what values."""
    notes, kept = _search(
        {"drift": (1.3, False), "offset": (0.3, True), "payload": (0.2, True)}, monkeypatch
    )
    assert kept == [["drift"]]
    assert len(notes) == 1
    assert "drift (scale 5) would remove 130%" in notes[0]


def test_pairs_are_free_where_no_single_effect_explains_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The same, the drift held at its bound removing too little to be named anyway: the
    pairs are fitted among all, as where every single effect is meaningful; no note."""
    for drift in ((0.3, False), (0.3, True)):
        notes, kept = _search(
            {"drift": drift, "offset": (0.3, True), "payload": (0.2, True)}, monkeypatch
        )
        assert notes == []
        assert kept == [[]]


def test_only_pairs_with_the_effect_beyond_its_range_are_fitted(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """fitted_pairs itself: with a drift beyond its range, drift + offset and drift +
    payload are fitted, offset + payload is not; without, all three."""
    loop = _loop({})
    monkeypatch.setattr(pairs_module, "refit", lambda *_a, **_k: ([], None))
    monkeypatch.setattr(pairs_module, "fit_cost", lambda *_a: 0.0)
    monkeypatch.setattr(
        pairs_module, "rescanned", lambda *_a, pair, own, result, **_k: (pair, own, result)
    )
    loop._step = lambda *_a: _step("pair", 0.0, meaningful=True)  # type: ignore[method-assign]
    drift, offset, payload = (
        _step("drift", 1.3, meaningful=False),
        _step("offset", 0.3, meaningful=True),
        _step("payload", 0.2, meaningful=True),
    )
    base = Base(np.full(N, LEFT), LEFT, 0.0, FLOOR, [], [])
    fitted_pairs(loop, [], [], [drift, offset, payload], base, beyond=[drift])
    tried = sorted(t for t in loop.said if t.startswith("trying"))  # type: ignore[attr-defined]
    assert tried == ["trying drift + offset", "trying drift + payload"]
    loop.said.clear()  # type: ignore[attr-defined]
    fitted_pairs(loop, [], [], [drift, offset, payload], base)
    tried = sorted(t for t in loop.said if t.startswith("trying"))  # type: ignore[attr-defined]
    assert len(tried) == 3
    assert "trying offset + payload" in tried


def test_the_note_names_each_effect_with_its_values_and_share() -> None:
    note = out_of_range([_step("drift", 1.334, meaningful=False)])
    assert "drift (scale 5) would remove 133% of the held-out error" in note


def test_a_pair_the_problem_refuses_takes_no_finalists_place(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Only the best few pairs (PAIR_FINALISTS) are refitted with the effects found before
    them. A pair the problem refuses whatever it fits (``accepts``: a drop test's rail
    friction its falls contradict) is left out before they are chosen: on zoo_13822 two
    backlash-and-rail pairs took two of the three places and the true pair (a backlash and
    an offset), fourth, was never refitted. Here the rail pairs fit best."""
    loop = _loop({})
    loop.problem.accepts = lambda effects, _p: all(e.name != "rail" for e in effects)
    cost = {"weight": 0.0, "rail": 0.0, "backlash": 1.0, "drift": 2.0, "offset": 4.0, "wave": 8.0}
    monkeypatch.setattr(pairs_module, "refit", lambda _pr, effects, _x, **_k: (effects, None))
    monkeypatch.setattr(
        pairs_module, "fit_cost", lambda _pr, _e, own, _r: sum(cost[e.name] for e in own)
    )
    finalists: list[list[str]] = []

    def rescanned(*_a: Any, pair: list[Any], own: Any, result: Any, **_k: Any) -> Any:
        finalists.append([e.name for e in pair])
        return pair, own, result

    monkeypatch.setattr(pairs_module, "rescanned", rescanned)
    loop._step = lambda *_a: _step("pair", 0.0, meaningful=True)  # type: ignore[method-assign]
    singles = [
        _step(n, 0.3, meaningful=True) for n in ("rail", "backlash", "drift", "offset", "wave")
    ]
    base = Base(np.full(N, LEFT), LEFT, 0.0, FLOOR, [], [])
    weight = SimpleNamespace(name="weight", fittable=False)
    fitted_pairs(loop, [weight], [np.array([1.0])], singles, base)
    assert finalists == [["backlash", "drift"], ["backlash", "offset"], ["drift", "offset"]]
    tried = [t for t in loop.said if t.startswith("trying")]  # type: ignore[attr-defined]
    assert "trying rail + backlash" in tried  # (fitted, then refused)
