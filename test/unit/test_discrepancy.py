"""The discrepancy tool on synthetic campaigns with concealed effects (the generator writes the
labels to a file the tool never reads; the test reads them to score)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from transparency_ros.analysis.discrepancy.discover import Discoverer, discover
from transparency_ros.analysis.discrepancy.drop_effects import (
    DropDrift,
    DropOffset,
    DropRestitution,
    HubArmCompliance,
)
from transparency_ros.analysis.discrepancy.effects import ParameterDrift, library
from transparency_ros.analysis.discrepancy.findings import Finding, Report, parameters_text, widen
from transparency_ros.analysis.discrepancy.fitting import held_at
from transparency_ros.analysis.discrepancy.model import Trial, load_nominal
from transparency_ros.analysis.discrepancy.steps import Base, Step, choose, null_inside
from transparency_ros.core import strict_json
from transparency_ros.core.errors import ConfigError
from transparency_ros.synth.campaign import OUTSIDE, write_campaign


def campaign(tmp_path: Path, hidden: list[str], seed: int = 1) -> tuple[object, dict]:
    out = write_campaign(tmp_path / "campaign", seed, hidden=hidden)
    trials = [
        Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
        for f in sorted((out / "data").glob("*.csv"))
    ]
    report = discover(load_nominal(out / "nominal.yaml"), trials)
    labels = json.loads((out / "labels.json").read_text())["hidden"]
    return report, labels


# effect -> (parameter, relative tolerance) checked against the label
SINGLE = {
    "torque_offset": ("offset_nm", 0.1),
    "cogging": ("amplitude_nm", 0.15),
    "payload_gravity": ("mgl_nm", 0.15),
    "torque_saturation": ("limit_nm", 0.1),
    "sensor_delay": ("delay_s", 0.15),
}


# These tests check naming and measuring; how often weak draws are missed is the benchmark's
# business (recall). Seed 1 draws a 7 ms delay whose signature sits at the noise floor; seed 2
# draws 15 ms.
SEEDS = {"sensor_delay": 2}


@pytest.mark.parametrize("effect", sorted(SINGLE))
def test_a_single_concealed_effect_is_found_named_and_measured(tmp_path: Path, effect: str) -> None:
    report, labels = campaign(tmp_path, [effect], seed=SEEDS.get(effect, 1))
    assert [f.effect for f in report.findings] == [effect]  # type: ignore[attr-defined]
    finding = report.findings[0]  # type: ignore[attr-defined]
    name, tolerance = SINGLE[effect]
    assert finding.parameters[name] == pytest.approx(labels[effect][name], rel=tolerance)
    if effect == "cogging":
        assert finding.parameters["cycles_per_rev"] == labels[effect]["cycles_per_rev"]
    assert finding.heldout_rmse_after <= 0.5 * finding.heldout_rmse_before
    assert finding.where["phase"] in {"stuck", "reversal", "slow", "fast"}
    assert report.unexplained == []  # type: ignore[attr-defined]


def test_a_wrong_nominal_parameter_is_named_with_its_refitted_value(tmp_path: Path) -> None:
    report, labels = campaign(tmp_path, ["parameter_drift"])
    (finding,) = report.findings  # type: ignore[attr-defined]
    assert finding.effect == "parameter_drift"
    scales = finding.parameters
    assert scales["viscous_scale"] == pytest.approx(
        labels["parameter_drift"]["viscous_scale"], rel=0.1
    )
    others = [scales[k] for k in ("inertia_scale", "coulomb_scale", "gravity_scale")]
    assert all(abs(s - 1.0) < 0.2 for s in others)


def test_no_effect_no_finding(tmp_path: Path) -> None:
    report, labels = campaign(tmp_path, [])
    assert labels == {}
    assert report.findings == [] and report.unexplained == []  # type: ignore[attr-defined]


def test_an_effect_outside_the_library_is_unexplained_not_forced(tmp_path: Path) -> None:
    report, labels = campaign(tmp_path, [OUTSIDE])
    assert report.findings == []  # type: ignore[attr-defined]
    assert report.unexplained  # type: ignore[attr-defined]
    # and what it looks like: an oscillation at the hidden ripple's frequency
    truth = labels[OUTSIDE]["frequency_hz"]
    for item in report.unexplained:  # type: ignore[attr-defined]
        assert item["dominant_frequency_hz"] == pytest.approx(truth, abs=0.5)
    assert all("noise floor" in u["looks_like"] for u in report.unexplained)  # type: ignore[attr-defined]
    # a torque that follows time, not the joint's state: position and velocity do not predict it
    for item in report.unexplained:  # type: ignore[attr-defined]
        assert item["state_explained_fraction"] < 0.3
        assert "not a function of the state" in item["looks_like"]


def test_a_leftover_that_is_physics_of_the_state_is_told_apart(tmp_path: Path) -> None:
    # cogging is a function of position; with cogging taken out of the library the tool must
    # leave it unexplained and say that position and velocity predict it
    out = write_campaign(tmp_path / "campaign", 3, hidden=["cogging"])
    trials = [
        Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
        for f in sorted((out / "data").glob("*.csv"))
    ]
    report = discover(
        load_nominal(out / "nominal.yaml"),
        trials,
        candidates=[e for e in library() if e.name != "cogging"],
    )
    assert report.unexplained
    for item in report.unexplained:
        assert item["state_explained_fraction"] > 0.3
        assert "not a function of the state" not in item["looks_like"]


def test_a_drift_pinned_at_its_bound_names_nothing() -> None:
    drift = ParameterDrift()
    assert drift.meaningful(np.array([1.0, 2.0, 1.0, 1.0]))
    assert not drift.meaningful(np.array([1.0, 1.1, 1.0, 1.0]))  # within 20 %: nothing wrong
    assert not drift.meaningful(np.array([1.0, 5.0, 1.0, 1.0]))  # held at the upper bound
    assert not drift.meaningful(np.array([0.2, 1.0, 1.0, 1.0]))  # inertia cut to a fifth
    assert drift.meaningful(np.array([1.0, 1.0, 0.0, 1.0]))  # no Coulomb friction at all


def test_nominal_specs_are_validated(tmp_path: Path) -> None:
    spec = tmp_path / "nominal.yaml"
    spec.write_text("inertia_kgm2: 0.1\nfriction: 2\n")
    with pytest.raises(ConfigError, match="unknown nominal terms"):
        load_nominal(spec)
    spec.write_text("viscous_nms_per_rad: 0.1\n")
    with pytest.raises(ConfigError, match="inertia_kgm2 is required"):
        load_nominal(spec)
    dfki = Path("/nonexistent")
    with pytest.raises(ConfigError, match="cannot read"):
        load_nominal(dfki)


def test_import_csv_then_discrepancy_json_and_report(tmp_path: Path) -> None:
    from transparency_ros.cli import main  # noqa: PLC0415

    out = write_campaign(tmp_path / "campaign", 1, hidden=["torque_offset"], trials=4)
    csvs = sorted(str(f) for f in (out / "data").glob("*.csv"))
    import lzma  # noqa: PLC0415

    packed = Path(csvs[0] + ".xz")  # one file as the lab's come: xz-compressed
    packed.write_bytes(lzma.compress(Path(csvs[0]).read_bytes()))
    Path(csvs[0]).unlink()
    csvs[0] = str(packed)
    assert main(["import-csv", *csvs, "--out", str(tmp_path / "bags")]) == 0
    bags = sorted((tmp_path / "bags").iterdir())
    assert len(bags) == 4 and all((b / "metadata.yaml").exists() for b in bags)
    assert [b.name for b in bags] == [Path(c).name.split(".")[0] for c in csvs]
    import contextlib  # noqa: PLC0415
    import io  # noqa: PLC0415

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = main(
            [
                "discrepancy",
                str(tmp_path / "bags"),
                "--nominal",
                str(out / "nominal.yaml"),
                "--json",
                "--report",
                str(tmp_path / "report"),
            ]
        )
    assert code == 0
    result = strict_json.loads(buffer.getvalue())
    assert [f["effect"] for f in result["findings"]] == ["torque_offset"]
    finding = result["findings"][0]
    assert set(finding) >= {
        "effect",
        "parameters",
        "where",
        "evidence",
        "confidence_interval",
        "heldout_rmse_before",
        "heldout_rmse_after",
        "channel",
    }
    assert finding["channel"] == "simulation"
    assert finding["where"]["unit"] == "rad"
    assert finding["where"]["phase"] in finding["where"]["rmse_reduction_by_phase"]
    low, high = finding["confidence_interval"]["offset_nm"]
    assert low <= finding["parameters"]["offset_nm"] <= high
    assert result["final_heldout_rmse"] < result["heldout_rmse_nominal"]
    assert (tmp_path / "report" / "discrepancy.png").stat().st_size > 0
    assert "torque_offset" in (tmp_path / "report" / "improvement.md").read_text()


def test_drop_tests_of_several_actuators_are_refused_clearly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from transparency_ros.cli import main  # noqa: PLC0415

    bags = Path(__file__).resolve().parents[2] / "bags"
    assert main(["discrepancy", str(bags / "U10DD"), str(bags / "EC60")]) == 2
    assert "one actuator per analysis" in capsys.readouterr().err


def test_effects_that_explain_alike_are_alternatives_and_the_simpler_is_named(
    tmp_path: Path,
) -> None:
    # seed 123: a payload's gravity on a joint that turns only +-0.7 rad, where sin q and
    # cogging's sin 2q fit the held-out data within 5 % of each other
    out = write_campaign(tmp_path / "campaign", 123)
    assert list(json.loads((out / "labels.json").read_text())["hidden"]) == ["payload_gravity"]
    trials = [
        Trial(f.stem, *np.loadtxt(f, delimiter=",", skiprows=1).T)
        for f in sorted((out / "data").glob("*.csv"))
    ]
    report = discover(load_nominal(out / "nominal.yaml"), trials)
    (finding,) = report.findings
    assert finding.effect == "payload_gravity"
    assert "cogging" in finding.alternatives
    assert "explained alike by" in finding.evidence


def _step(effect: object, p: list[float], rmse: float, floor: float) -> Step:
    """A single added effect's step of held-out ``rmse``, judged against ``floor``."""
    n = 10_000
    return Step(
        added=[effect],
        params=[np.array(p)],
        err=np.full(n, rmse),
        rmse=rmse,
        aic=n * np.log(rmse**2) + 2 * len(p),
        gain=0.9,
        judged=(5.0, rmse, floor),
        result=None,
        meaningful=True,
    )


def test_a_rebound_yields_to_a_spring_that_explains_alike_and_not_to_a_worse_one() -> None:
    """Between a contact's rebound and a hub-arm spring of as many parameters that explain the
    held-out data within 5 %, the spring is named though the rebound fits a little better; a
    rebound that fits clearly better (10 %) is named."""
    rebound, spring = DropRestitution(), HubArmCompliance(loaded_inertia_kgm2=0.01)

    def step(effect: object, rmse: float) -> Step:
        return _step(effect, [0.5, 6.0], rmse, 1e-4)  # above the floor

    chooser = Discoverer.__new__(Discoverer)
    chooser.problem = object()
    alike = chooser._choose([step(rebound, 1.00e-3), step(spring, 1.03e-3)])
    assert alike is not None and alike.added == [spring]
    assert alike.alternatives == ["restitution"]
    better = chooser._choose([step(rebound, 1.00e-3), step(spring, 1.10e-3)])
    assert better is not None and better.added == [rebound]


def test_a_drift_holds_the_terms_that_did_not_drift() -> None:
    """A drift fitted with all three terms is reduced to those off nominal by more than
    DRIFT_MIN; the held ones are reported as scales of 1 and act as nominal."""
    full = DropDrift()
    reduced = full.reduced(np.array([0.991, 1.0, 1.32]))
    assert reduced is not None
    coulomb, start = reduced
    assert coulomb.free == (False, False, True)
    assert coulomb.param_names == ("coulomb_scale",)
    assert start.tolist() == [1.32]
    assert coulomb.yields_to == 1 and full.yields_to == 0
    assert coulomb.extra_parameters(start) == {"reflected_inertia_scale": 1.0, "viscous_scale": 1.0}
    assert coulomb.scales(np.array([1.5])).tolist() == [1.0, 1.0, 1.5]
    two = full.reduced(np.array([1.7, 1.05, 1.5]))
    assert two is not None and two[0].free == (True, False, True) and two[0].yields_to == 0
    assert full.reduced(np.array([1.0, 1.01, 0.99])) is None  # nothing drifted: nothing to hold
    assert full.reduced(np.array([1.7, 0.5, 1.5])) is None  # every term drifted
    assert coulomb.reduced(np.array([1.32])) is None


def test_an_offset_is_named_over_a_coulomb_drift_that_explains_alike() -> None:
    """A Coulomb drift alone and a constant offset (one parameter each) that fit the held-out
    data alike: the offset is named, the drift given as the alternative. A Coulomb drift that
    fits clearly better (10 %) is named."""
    coulomb = DropDrift((False, False, True))
    offset = DropOffset(0.03)

    def step(effect: object, rmse: float) -> Step:
        return _step(effect, [1.5], rmse, 1e-4)  # above the floor

    alike = choose([step(coulomb, 1.00e-3), step(offset, 1.00e-3)], lambda _e, _p: False)
    assert alike is not None and alike.added == [offset]
    assert alike.alternatives == ["parameter_drift"]
    better = choose([step(coulomb, 1.00e-3), step(offset, 1.10e-3)], lambda _e, _p: False)
    assert better is not None and better.added == [coulomb]


def test_steps_that_both_reach_the_noise_floor_are_alike() -> None:
    """Two steps that both explain the held-out data down to its noise floor cannot be told
    apart, however far apart their RMSEs: the one with fewer parameters is named. Above the
    floor the better one is."""
    drift, offset = DropDrift(), DropOffset(0.03)

    steps = [_step(drift, [1.04, 0.99, 0.0], 0.31, 1.0), _step(offset, [0.07], 0.49, 1.0)]
    below = choose(steps, lambda _e, _p: False)
    assert below is not None and below.added == [offset]
    assert below.alternatives == ["parameter_drift"]
    steps = [_step(drift, [1.04, 0.99, 0.0], 1.31, 1.0), _step(offset, [0.07], 1.49, 1.0)]
    above = choose(steps, lambda _e, _p: False)
    assert above is not None and above.added == [drift]


def test_widen_logs_in_their_natural_unit_and_derived_values_follow() -> None:
    """A logarithm's interval is widened by the model's share of its natural value, and a
    value derived from it (a stiffness, its frequency) gets the interval its corners give."""
    effect = HubArmCompliance(loaded_inertia_kgm2=0.01)
    p = np.array([3.0, 0.05])
    finding = Finding(
        effect=effect.name,
        parameters={"log10_hub_arm_stiffness_nm_per_rad": 3.0, "damping_ratio": 0.05}
        | effect.extra_parameters(p),
        confidence_interval={
            "log10_hub_arm_stiffness_nm_per_rad": (2.99, 3.01),
            "damping_ratio": (0.04, 0.06),
        },
        where={},
        evidence="",
        heldout_rmse_before=1.0,
        heldout_rmse_after=0.5,
    )
    report = Report(nominal={}, split={}, findings=[finding], fitted=[(effect, p)])
    widen(report, 0.2)
    ci = report.findings[0].confidence_interval
    lo, hi = ci["log10_hub_arm_stiffness_nm_per_rad"]
    assert hi - 3.0 == pytest.approx(np.hypot(0.01, np.log10(1.2)))
    assert lo == pytest.approx(3.0 - (hi - 3.0))
    assert ci["damping_ratio"][1] - 0.05 == pytest.approx(np.hypot(0.01, 0.2 * 0.05))
    assert ci["hub_arm_stiffness_nm_per_rad"] == pytest.approx((10**lo, 10**hi))
    f_lo, f_hi = ci["compliance_hz"]
    assert f_lo < effect.extra_parameters(p)["compliance_hz"] < f_hi
    assert f_hi / f_lo == pytest.approx(np.sqrt(10 ** (hi - lo)))
    assert "compliance_hz 50.33 (95 % " in parameters_text(report.findings[0])


def test_a_parameter_held_at_its_null_bound_is_not_told_from_nothing() -> None:
    """A rebound whose fit ends on e = 0 (the bound of its range and its null value) has a
    zero-width interval there, 0.000 (0.000 to 0.000): that is no rebound, not one measured
    exactly. The same coefficient fitted inside its range with an interval away from 0
    is told from nothing."""
    rebound = DropRestitution()
    lower, upper = np.array(rebound.lower), np.array(rebound.upper)
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(400, 2))

    def step(e: float) -> Step:
        x = np.array([e, 6.4])
        result = SimpleNamespace(
            x=x, jac=jac, fun=1e-4 * rng.normal(size=400), cost=1e-6, lower=lower, upper=upper
        )
        return Step(
            added=[rebound],
            params=[x],
            err=np.zeros(1),
            rmse=1.0,
            aic=0.0,
            gain=0.9,
            judged=(1.0, 0.1, 0.01),
            result=result,
            meaningful=True,
        )

    at_null = step(1e-6)
    assert held_at(at_null.result, at_null.result.x)(0, 0.0)
    assert null_inside(at_null)
    inside = step(0.3)
    assert not held_at(inside.result, inside.result.x)(0, 0.0)
    assert not null_inside(inside)


def test_a_wave_whose_period_stands_out_of_the_scan_is_judged_by_its_prominence() -> None:
    """A cogging step removing 0.45 of the error above the floor (under the uniform 0.75):
    named where its period's waves removed prominent_wave(M) times what the median period's
    did, M the periods its scan could tell apart, over WAVE_CYCLES periods of the arm's
    travel; not with the same prominence over one period (a smooth torque any low period
    imitates), nor with an ordinary one. A scan that told more periods apart asks more (the
    largest of more periods stands out further by chance): a prominence enough among 20 is
    not among 300. An ordinary one is named where every trial shows the same wave (its spread
    at most REPLICATED_SPREAD) over REPLICATED_CYCLES periods, not over fewer, nor with a
    wider or unmeasured spread. A pair's wave keeps the uniform share; a step without a
    scanned choice is judged as before."""
    from transparency_ros.analysis.discrepancy import steps as d  # noqa: PLC0415

    loop = Discoverer(SimpleNamespace(min_improvement=0.75))  # type: ignore[arg-type]
    wave = DropOffset(0.03)  # (any effect: what is judged is the step's scan)

    def step(
        gain: float,
        prominence: float | None,
        cycles: float,
        added: int = 1,
        *,
        spread: float = math.nan,
        independent: float = 20.0,
    ) -> Step:
        s = _step(wave, [0.05], 1e-3, 1e-4)
        s.added = [wave] * added
        s.gain = gain
        s.scanned = [] if prominence is None else [(prominence, cycles, spread, independent)]
        return s

    stands_out = d.prominent_wave(20.0)
    assert loop._share(step(0.45, stands_out, d.WAVE_CYCLES)) == 0.0
    assert loop._share(step(0.45, stands_out, 1.1)) == 0.75
    assert loop._share(step(0.45, stands_out - 1, 10.0)) == 0.75
    assert loop._share(step(0.45, stands_out, 10.0, independent=300.0)) == 0.75
    assert loop._share(step(0.45, stands_out * 3, 10.0, added=2)) == 0.75
    assert loop._share(step(0.45, None, 0.0)) == 0.75
    alike = d.REPLICATED_SPREAD
    assert loop._share(step(0.1, 2.0, d.REPLICATED_CYCLES, spread=alike)) == 0.0
    assert loop._share(step(0.1, 2.0, d.REPLICATED_CYCLES - 0.1, spread=alike)) == 0.75
    assert loop._share(step(0.1, 2.0, 10.0, spread=alike + 0.1)) == 0.75
    assert loop._share(step(0.1, 2.0, 10.0)) == 0.75
    assert loop._share(step(0.1, 2.0, 10.0, added=2, spread=0.0)) == 0.75


def test_the_prominence_a_wave_needs_is_a_peak_test_over_the_periods_told_apart() -> None:
    """prominent_wave(M): the prominence the largest of M periods reaches by chance with
    probability WAVE_FALSE_ALARM, where each period's removed error is exponential (its
    median ln 2 of its mean): M 2^-t = alpha. Checked on drawn periodograms: against their
    true median, the rate is alpha; against the median of the same M draws (the scan's own
    level, itself scattered), a few times alpha and under 5 % for M of 10-100 (the zoo, not
    this model, sets the rule: benchmarks/prominence_calibration.py)."""
    from transparency_ros.analysis.discrepancy import steps as d  # noqa: PLC0415

    assert d.prominent_wave(28.0) == pytest.approx(math.log2(28.0 / d.WAVE_FALSE_ALARM))
    assert d.prominent_wave(0.2) == d.prominent_wave(1.0)  # (one period at least)
    assert d.prominent_wave(10.0) < d.prominent_wave(30.0) < d.prominent_wave(300.0)
    rng = np.random.default_rng(7)
    for m in (10, 30, 100):
        draws = rng.exponential(size=(40000, m))
        known = np.mean(draws.max(axis=1) / math.log(2) >= d.prominent_wave(m))
        assert known == pytest.approx(d.WAVE_FALSE_ALARM, rel=0.3), m
        own = np.mean(draws.max(axis=1) / np.median(draws, axis=1) >= d.prominent_wave(m))
        assert d.WAVE_FALSE_ALARM < own < 0.05, (m, own)


def test_a_phase_above_the_leftover_is_unexplained_where_the_whole_residual_is_not() -> None:
    """What the report calls unexplained, and what opens the search to pairs (zoo_12167: a
    delay and an offset left 2.8x the noise floor in all, 7x at the impact): a phase of 50
    held-out elements at least whose RMS is above LEFTOVER times the floor."""
    from transparency_ros.analysis.discrepancy.findings import (  # noqa: PLC0415
        LEFTOVER,
        MIN_PHASE,
        unexplained_phases,
    )

    n = 1000
    impact = np.zeros(n, dtype=bool)
    impact[:100] = True
    short = np.zeros(n, dtype=bool)
    short[100 : 100 + MIN_PHASE - 1] = True
    problem = SimpleNamespace(
        noise_floor=lambda: 1.0,
        phases=lambda: {"impact": impact, "short": short, "rest": ~(impact | short)},
    )
    err = np.ones(n)
    err[impact] = 7.0
    err[short] = 50.0  # too few elements to judge
    assert float(np.sqrt(np.mean(err[~short] ** 2))) < LEFTOVER  # the whole is below
    found = unexplained_phases(problem, err)  # type: ignore[arg-type]
    assert found == {"impact": pytest.approx(7.0)}
    err[impact] = 0.99 * LEFTOVER
    assert unexplained_phases(problem, err) == {}  # type: ignore[arg-type]


def test_one_sensors_error_above_its_own_floor_is_unexplained_where_the_pooled_is_not() -> None:
    """zoo_13118 (an offset of -0.032 N m hidden, nothing named): the encoder's held-out error
    was 8x its own floor, the pooled error within the floor the heights' noise sets, and the
    report said nothing was left. Now it says so, on that sensor, in the phase holding most
    of it, with the candidate that came closest; not where a phase is unexplained pooled, and
    not where the sensor is within LEFTOVER times its floor."""
    from transparency_ros.analysis.discrepancy.findings import (  # noqa: PLC0415
        LEFTOVER,
        MIN_PHASE,
        leftover,
    )

    n = 400
    encoder = np.arange(n) < 2 * MIN_PHASE
    impact = np.arange(n) < MIN_PHASE // 2  # a quarter of the encoder's elements
    pooled_floor, own_floor = 10.0, 0.1
    err = np.full(n, 9.0)  # the heights: within their floor pooled, below LEFTOVER of it
    err[encoder] = 0.2
    err[impact] = 2.0  # the encoder's error sits at the impact

    def scope(e: np.ndarray) -> tuple[np.ndarray, float] | None:
        return (encoder, own_floor) if np.sqrt(np.mean(e[encoder] ** 2)) > 1.5 * own_floor else None

    problem = SimpleNamespace(
        noise_floor=lambda: pooled_floor,
        phases=lambda: {"impact": impact, "deflection": ~impact},
        leftover_scope=scope,
        scoped_sensor="encoder",
        residual_peak_hz=lambda *_a: 40.0,
    )
    (entry,) = leftover(problem, err, closest=(["torque_offset"], 0.74))  # type: ignore[arg-type]
    own = float(np.sqrt(np.mean(err[encoder] ** 2)))
    assert own > LEFTOVER * own_floor
    assert entry["where"] == {"phase": "impact", "sensor": "encoder"}
    assert entry["rmse_rad"] == pytest.approx(own)
    assert entry["noise_floor_rad"] == own_floor
    assert entry["dominant_frequency_hz"] is None  # the pooled residual's peak is not its
    assert f"encoder's residual {own / own_floor:.0f}x its own noise floor" in entry["looks_like"]
    assert entry["closest_candidate"] == {
        "effect": "torque_offset", "effects": ["torque_offset"], "share_removed": 0.74,
    }  # fmt: skip
    assert "torque_offset, would remove 74%" in entry["looks_like"]
    # within LEFTOVER times its floor: nothing is said
    err[encoder] = 0.9 * LEFTOVER * own_floor
    assert leftover(problem, err) == []  # type: ignore[arg-type]
    # a phase unexplained pooled is said as before, and the sensor's part is not added
    err[impact] = 2.0
    err[~encoder] = 2 * LEFTOVER * pooled_floor
    found = leftover(problem, err)  # type: ignore[arg-type]
    assert [e["where"] for e in found] == [{"phase": "deflection"}]


def test_a_step_judged_on_an_error_at_its_floor_already_removes_a_share_of_all_of_it() -> None:
    """A sensor's effect is judged on that sensor's error and floor: the share of the error
    above the floor it removes. Where that error is at or under its floor already, the floor
    is no floor (an estimate the step went below) and the share is of all of it, not the
    removal over a vanishing denominator (zoo_12214: an encoder error of 0.279 mrad under its
    floor of 0.443; a 0.25 ms sensor delay took 0.075 mrad off it, a share of 7.5e7, and was
    named on a campaign hiding nothing; robot zoo 928: a 6 ms delay took a joint's error from
    0.93 to 0.35 of its floor, a share of all of it of 0.62)."""
    n = 200
    sensor = np.arange(n) < n // 2  # the encoder's half of the pooled held-out error
    effect = SimpleNamespace(discrete_choices=0, meaningful=lambda _p: True)

    def judged_share(before: float, after: float, floor: float) -> float:
        base_err = np.where(sensor, before, 10.0)  # the pooled error far above its floor
        err = np.where(sensor, after, 10.0)
        problem = SimpleNamespace(
            error=lambda _e, _p, _h: err, sensor_scope=lambda _a, _s, _m: (sensor, floor)
        )
        loop = Discoverer.__new__(Discoverer)
        loop.problem = problem
        base = Base(base_err, 10.0, 0.0, 1.0)
        step = loop._step([], [np.array([2.5e-4])], [effect], None, base)
        assert step.judged == pytest.approx((before, after, floor))
        return step.gain

    assert judged_share(2.0e-3, 1.0e-3, 0.5e-3) == pytest.approx(2 / 3)  # above: its share
    assert judged_share(0.279e-3, 0.204e-3, 0.443e-3) == pytest.approx(0.075 / 0.279)  # under
    assert judged_share(0.93, 0.35, 1.0) == pytest.approx(0.58 / 0.93)
    assert judged_share(0.443e-3, 0.3e-3, 0.443e-3) == pytest.approx(0.143 / 0.443)  # at it
    assert judged_share(0.0, 0.0, 0.443e-3) == 0.0
