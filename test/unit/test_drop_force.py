"""The load cell while the shuttle rides the arm (drop_force): its residual in its own
uncertainty, and the loop's last stage, which searches it for what the encoder does not show."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.drop import (
    DropProblem,
    load_drop_nominal,
    load_drop_trial,
)
from transparency_ros.analysis.discrepancy.drop_force import (
    BIN_S,
    FORCE_SIGNIFICANT,
    SETTLE_S,
    ForceView,
    _Bins,
)
from transparency_ros.analysis.discrepancy.findings import Report
from transparency_ros.bag.reader import find_bags
from transparency_ros.synth.drop_campaign import write_drop_campaign


def _problem(tmp_path: Path) -> DropProblem:
    out = write_drop_campaign(tmp_path / "c", 3, hidden=["payload_gravity"], actuator="EC60")
    trials = [load_drop_trial(b) for b in find_bags([str(out / "bags")])]
    return DropProblem(trials, load_drop_nominal(None, trials))


def _named(problem: DropProblem, name: str) -> object:
    return next(c for c in problem.candidates() if c.name == name)


def _self_simulated(problem: DropProblem, *, weighed: bool = True, **changes: float) -> ForceView:
    """The problem's load-cell view with its measured bins, and the problem's encoder and
    height readings, replaced by the tool's own simulation (the shuttle's weight on, and
    ``changes`` to its physics), plus noise (of one uncertainty in the bins). ``weighed``
    False: the encoder and heights without the weight."""
    weight = _named(problem, "payload_gravity")
    rng = np.random.default_rng(11)
    for s in (problem.fit, problem.held):  # the encoder and heights alike
        on = [weight] if weighed else []
        ph = problem.physics(on, [problem.initial(weight)][: len(on)], s.trials)
        t_sim, q_sim, y_sim = s.sim.run(replace(ph, **changes))
        for i, ((t_q, _q), (t_h, _h)) in enumerate(zip(s.q, s.h, strict=True)):
            s.q[i] = (t_q, np.interp(t_q, t_sim, q_sim[i]) + rng.normal(0, 2e-5, t_q.size))
            s.h[i] = (t_h, np.interp(t_h, t_sim, y_sim[i]) + rng.normal(0, 2e-5, t_h.size))
    view = ForceView(problem)
    for bins in (view.fit, view.held):
        ph = problem.physics([weight], [problem.initial(weight)], bins.trials)
        residual = bins.error_many([replace(ph, **changes)])[0]
        k = 0
        for i, sigma in enumerate(bins.sigma):
            n = sigma.size
            model = bins.measured[i] - residual[k : k + n] * sigma
            bins.measured[i] = model + rng.normal(0.0, 1.0, n) * sigma
            k += n
    return view


def _last_stage(
    problem: DropProblem, view: ForceView
) -> tuple[Report, list[object], list[np.ndarray], np.ndarray, np.ndarray]:
    """The loop's last stage on ``view``, the shuttle's weight found before it: (report,
    effects, parameters, held-out error after, held-out error before)."""
    problem.force_view = lambda: view  # type: ignore[method-assign]
    weight = _named(problem, "payload_gravity")
    report = Report(problem.nominal, problem.split)
    before = problem.error([weight], [problem.initial(weight)], True)
    effects, params, held = Discoverer(problem)._on_load_cell(
        report, [weight], [problem.initial(weight)], before
    )
    return report, effects, params, held, before


def test_the_ride_is_compared_in_its_uncertainty_from_after_the_strike(tmp_path: Path) -> None:
    """Bins start after the strike's pulse, inside the recording, with positive
    uncertainties; the tool's own simulation plus noise of one uncertainty reads as about one
    uncertainty (no structure), and a torque of 0.05 N m on the arm as structure."""
    problem = _problem(tmp_path)
    view = _self_simulated(problem)
    weight = _named(problem, "payload_gravity")
    for bins in (view.fit, view.held):
        assert bins.size >= 10
        for trial, times, sigma in zip(bins.trials, bins.times, bins.sigma, strict=True):
            assert times[0] > trial.contact_s and times[-1] < trial.end_s
            assert np.all(sigma > 0)
    err = view.error([weight], [problem.initial(weight)], True)
    assert 0.7 < float(np.sqrt(np.mean(err**2))) < 1.3
    assert not view.structure_left(err)
    offset = _named(problem, "torque_offset")
    pushed = view.error([weight, offset], [problem.initial(weight), np.array([0.05])], True)
    assert float(np.sqrt(np.mean(pushed**2))) > FORCE_SIGNIFICANT


def test_a_cogging_the_encoder_cannot_show_is_named_on_the_load_cell(tmp_path: Path) -> None:
    """The loop's last stage on a load cell that shows a cogging wave (N = 70, 0.03 N m):
    cogging is named there with its period within 2 and its size within 10 %, its evidence
    says the load cell, and the effect found before (the weight) keeps its value."""
    problem = _problem(tmp_path)
    view = _self_simulated(problem, cogging_nm=0.03, cogging_periods=70.0, cogging_phase_rad=0.8)
    report, effects, params, held, before = _last_stage(problem, view)
    assert [e.name for e in effects] == ["payload_gravity", "cogging"]
    assert np.array_equal(params[0], problem.initial(_named(problem, "payload_gravity")))
    assert abs(report.findings[-1].parameters["periods_per_rev"] - 70) <= 2
    assert report.findings[-1].parameters["amplitude_nm"] == pytest.approx(0.03, rel=0.1)
    assert "load cell" in report.findings[-1].evidence
    assert held.shape == before.shape


def test_nothing_is_named_on_a_load_cell_that_shows_nothing(tmp_path: Path) -> None:
    problem = _problem(tmp_path)
    report, effects, _, held, before = _last_stage(problem, _self_simulated(problem))
    assert [e.name for e in effects] == ["payload_gravity"] and not report.findings
    assert held is before


def test_an_effect_that_worsens_the_kinematics_is_not_meaningful_there(tmp_path: Path) -> None:
    """What the load cell alone would name must not cost the encoder and heights more than
    KINEMATICS_KEPT: a large offset is refused, none is accepted."""
    problem = _problem(tmp_path)
    view = ForceView(problem)
    weight = _named(problem, "payload_gravity")
    offset = _named(problem, "torque_offset")
    view.start([weight], [problem.initial(weight)])
    assert view.accepts([weight, offset], [problem.initial(weight), np.array([0.0])])
    assert not view.accepts([weight, offset], [problem.initial(weight), np.array([0.3])])


@pytest.mark.parametrize("shown", [True, False])
def test_the_weight_the_load_cell_reads_is_named_though_the_encoder_disagrees(
    tmp_path: Path, shown: bool
) -> None:
    """The declared weight is named where the load cell in the ride shows it (its residual
    from structure to within FORCE_SIGNIFICANT), even where the encoder's fit gets worse
    with it (a missing sensor delay did so on zoo_10297), and the evidence says so; where
    the load cell does not show it either, it is not named."""
    problem = _problem(tmp_path)
    view = _self_simulated(problem, weighed=False)
    if not shown:  # the load cell's bins without the weight as well
        for bins in (view.fit, view.held):
            residual = bins.error_many([problem.physics([], [], bins.trials)])[0]
            k = 0
            for i, sigma in enumerate(bins.sigma):
                bins.measured[i] = bins.measured[i] - residual[k : k + sigma.size] * sigma
                k += sigma.size
    problem.__dict__["_load_cell"] = view  # the problem's own view of its load cell
    weight = _named(problem, "payload_gravity")
    held = problem.error([], [], True)
    assert float(
        np.sqrt(np.mean(problem.error([weight], [problem.initial(weight)], True) ** 2))
    ) > (float(np.sqrt(np.mean(held**2))))  # the encoder and heights say no weight
    report = Report(problem.nominal, problem.split)
    effects, _, _ = Discoverer(problem)._declared(report, [], [], held, problem.noise_floor())
    assert ("payload_gravity" in [e.name for e in effects]) is shown
    if shown:
        assert "shown by the load cell in the ride" in report.findings[0].evidence
        assert "% higher" in report.findings[0].evidence


def _strike_again(
    bins: _Bins, trials: slice = slice(None), first: int = 4, flight: int = 4
) -> None:
    """In the ``trials`` of ``bins``, the shuttle leaves the arm (the load cell reads nothing
    for ``flight`` bins from bin ``first``) and strikes it again (a pulse of forty
    uncertainties in the next bin): what a rebound whose timing the model misses by a
    millisecond leaves."""
    for measured, sigma in zip(bins.measured[trials], bins.sigma[trials], strict=True):
        measured[first : first + flight] = 0.0
        measured[first + flight] += 40.0 * sigma[first + flight]


def test_the_ride_is_compared_from_after_the_shuttles_last_flight(tmp_path: Path) -> None:
    """Where the load cell reads the shuttle off the arm, the bins compared begin SETTLE_S
    after the last such bin (the re-strike's pulse left out), in that trial only; before the
    view is started on a model, every bin is compared."""
    problem = _problem(tmp_path)
    view = _self_simulated(problem)
    weight = _named(problem, "payload_gravity")
    held = view.held
    counts = [m.size for m in held.measured]
    assert held.size == sum(counts)
    first, flight = 4, 4
    _strike_again(held, slice(0, 1), first, flight)  # the first held-out trial only
    assert view.error([weight], [problem.initial(weight)], True).size == sum(counts)
    view.start([weight], [problem.initial(weight)])
    kept = held.kept_times()
    last = held.times[0][first + flight - 1]
    assert kept[0][0] >= last + BIN_S + SETTLE_S and kept[0].size < counts[0]
    assert kept[0][0] < last + BIN_S + SETTLE_S + 1.5 * BIN_S
    assert [k.size for k in kept[1:]] == counts[1:]
    err = view.error([weight], [problem.initial(weight)], True)
    assert err.size == held.size == sum(k.size for k in kept)
    assert 0.7 < float(np.sqrt(np.mean(err**2))) < 1.3  # the re-strike's pulse is not in it
    index, labels = view.segments()
    assert index.size == err.size and labels[0][1] == pytest.approx(float(kept[0][0]))


def test_a_cogging_is_named_though_the_shuttle_strikes_the_arm_again(tmp_path: Path) -> None:
    """zoo_13285's case (a rebound beside the cogging): a load cell that shows the cogging
    wave after every trial's shuttle left the arm and struck it again; the re-strikes' pulses
    (forty uncertainties, in bins the settled ride keeps at about one) would drown the wave.
    Cogging is named, its period within 2 and its size within 10 %."""
    problem = _problem(tmp_path)
    view = _self_simulated(problem, cogging_nm=0.03, cogging_periods=70.0, cogging_phase_rad=0.8)
    for bins in (view.fit, view.held):
        _strike_again(bins)
    report, effects, *_ = _last_stage(problem, view)
    assert [e.name for e in effects] == ["payload_gravity", "cogging"]
    assert abs(report.findings[-1].parameters["periods_per_rev"] - 70) <= 2
    assert report.findings[-1].parameters["amplitude_nm"] == pytest.approx(0.03, rel=0.1)
