"""The sensitivity assay (issue 27, part 5): pulses added to the command of runs without contact,
a detector's operating point at a false-alarm rate, its minimum detectable torque per joint.
Checked on a simulated chain whose truth differs from its URDF; the figures on the real double
pendulum are in docs/robots.md."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from transparency_ros.analysis import robot_assay as ra
from transparency_ros.analysis import robot_detect as rd
from transparency_ros.analysis.robot_calibration import calibrate
from transparency_ros.analysis.robot_data import JointRecording
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.robot_calibration import effort_limit
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.synth.robots import chain_urdf, simulate_chain

SHARED = Path(__file__).resolve().parents[1] / "data" / "double_pendulum"  # the lab's files


def quiet(seconds: float, joints: int = 2) -> JointRecording:
    n = round(seconds / 0.002)
    zeros = np.zeros((n, joints))
    stamps = (np.arange(n) * 2_000_000).astype(np.int64)
    names = tuple(f"j{i}" for i in range(joints))
    return JointRecording("quiet", stamps, names, zeros, zeros, zeros)


def spans(column: np.ndarray, t: np.ndarray) -> list[tuple[float, float, float]]:
    """(start, end, sign) of each run of non-zero samples."""
    on = column != 0
    starts = np.flatnonzero(on & ~np.r_[False, on[:-1]])
    ends = np.flatnonzero(on & ~np.r_[on[1:], False])
    return [(t[s], t[e], column[s]) for s, e in zip(starts, ends, strict=True)]


def test_pulses_come_one_per_joint_per_spacing_in_the_given_widths_and_reproducibly() -> None:
    rec = quiet(21.0, joints=3)
    settings = ra.AssaySettings(widths_s=(0.05, 0.1), spacing_s=1.0, seed=7)
    labels = ra.pulse_labels(rec, settings, placement=0)
    t = rec.stamps_ns * 1e-9
    assert set(np.unique(labels)) == {-1.0, 0.0, 1.0}
    for j in range(3):
        found = spans(labels[:, j], t)
        assert len(found) == 20  # one per second after the first half second
        assert found[0][0] >= ra.SETTLE_S
        widths = [end - start + 0.002 for start, end, _ in found]
        assert min(widths) >= 0.05 - 0.002 and max(widths) <= 0.1 + 0.002
        gaps = [b[0] - a[1] for a, b in itertools.pairwise(found)]
        assert min(gaps) >= ra.RECOVERY_S
        assert {s for _, _, s in found} == {-1.0, 1.0}
    assert not np.array_equal(labels[:, 0], labels[:, 1])  # each joint its own train
    assert np.array_equal(labels, ra.pulse_labels(rec, settings, placement=0))
    assert not np.array_equal(labels, ra.pulse_labels(rec, settings, placement=1))
    pushed = ra.with_pulses(rec, 2.5 * labels)
    assert np.array_equal(pushed.torque, -2.5 * labels) and pushed.label is not None
    assert np.array_equal(pushed.position, rec.position)  # the motion is the recorded one


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"widths_s": (0.1, 0.05)}, "pulse widths"),
        ({"spacing_s": 0.2}, "pulse spacing 0.2 s"),
        ({"placements": 0}, "placements 0"),
        ({"recall": 1.5}, "recall 1.5"),
        ({"alarms_per_minute": -1.0}, "alarms per minute -1.0"),
    ],
)
def test_settings_a_detector_cannot_be_assayed_at_are_refused(
    change: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        ra.AssaySettings(**change)  # type: ignore[arg-type]


def chain_run(truth: RobotModel, seconds: float, phase: float, every: int = 1) -> JointRecording:
    """The chain's run simulated at 1 kHz, every ``every``-th sample recorded."""
    n = round(seconds * 1000)
    stamps, q, v, command = simulate_chain(truth, np.zeros((n, truth.dof)), phase=phase)
    cut = slice(None, None, every)
    return JointRecording(
        f"run{phase:g}", stamps[cut], truth.joint_names, q[cut], v[cut], command[cut]
    )


def test_a_pulse_in_the_command_reaches_the_observer_as_an_external_torque_would() -> None:
    """The assay's premise, on the observer itself: the residual with the pulses is the one
    without plus the observer's own first-order response to them (each torque held until the
    next sample), joint by joint -- a pulse on one joint leaves the other's residual alone."""
    urdf = RobotModel.from_urdf(chain_urdf(2))
    truth = RobotModel.from_urdf(chain_urdf(2, mass=0.65))
    run = chain_run(truth, 4.0, 0.0)
    labels = ra.pulse_labels(run, ra.AssaySettings(), placement=0)
    labels[:, 1] = 0.0
    before = rd.textbook_residual(urdf, run, 20.0)
    after = rd.textbook_residual(urdf, ra.with_pulses(run, 1.5 * labels), 20.0)
    expected = np.zeros(labels.shape[0])
    dt = 1e-3
    for k in range(1, labels.shape[0]):
        expected[k] = expected[k - 1] + 20.0 * dt * (1.5 * labels[k - 1, 0] - expected[k - 1])
    assert np.abs(after[:, 0] - before[:, 0] - expected).max() < 1e-9
    assert np.abs(after[:, 1] - before[:, 1]).max() < 1e-9
    assert np.abs(expected).max() > 1.0  # the pulses did reach it


def test_the_calibrated_observer_detects_smaller_pulses_than_the_textbook_one() -> None:
    """A chain 30 % heavier than its URDF: the textbook observer's residual without contact is
    the model's error, the calibrated one's is small. Each detector at its own operating point
    (no more than one false alarm per minute on the runs without pulses) finds >= 90 % of the
    pulses at its minimum torque and fewer below it; the minimum lies where a pulse's rise
    through the observer meets the threshold over the residual without contact."""
    urdf = RobotModel.from_urdf(chain_urdf(2))
    truth = RobotModel.from_urdf(chain_urdf(2, mass=0.65))
    runs = [chain_run(truth, 5.0, phase, every=2) for phase in (0.0, 0.7, 1.4, 2.1)]
    settings = ra.AssaySettings()
    found = {}
    for name in ("calibrated", "textbook"):
        cases = []
        for train, held in ra.folds(runs, 2):
            fit = [runs[i] for i in train]
            if name == "calibrated":
                detector = ra.calibrated_detector(urdf, calibrate(urdf, fit, 20.0))
            else:
                detector = ra.textbook_detector(urdf, 20.0, fit)
            cases += [(detector, runs[i]) for i in held]
        found[name] = ra.assay(cases, settings, effort_limit(urdf))
        for j, s in enumerate(found[name]):
            assert s.alarms_per_minute <= 1.0 and s.minutes == pytest.approx(4 * 5 / 60, rel=0.01)
            assert s.min_torque_nm is not None and s.recall >= 0.9
            assert s.pulses == 4 * 4 * settings.placements
            below = [r for a, r in s.tried if a < s.min_torque_nm]
            assert below and max(below) < 0.9  # a smaller pulse is missed more often
            if name == "textbook":  # a constant threshold: bounds from the residual's size
                levels = [s.threshold_scale * d.threshold(r)[0, j] for d, r in cases]
                largest = max(np.abs(d.residual(r)[:, j]).max() for d, r in cases)
                rise = 1 - math.exp(-20.0 * (settings.widths_s[0] - 0.002))
                assert min(levels) <= s.threshold_nm <= max(levels)
                assert min(levels) - largest <= s.min_torque_nm
                assert s.min_torque_nm <= (max(levels) + largest) / rise * 1.05
    for cal, tb in zip(found["calibrated"], found["textbook"], strict=True):
        assert cal.min_torque_nm is not None and tb.min_torque_nm is not None
        assert cal.min_torque_nm < 0.5 * tb.min_torque_nm


def test_runs_too_few_for_the_folds_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"2 run\(s\) for 3 folds"):
        ra.folds([quiet(1.0), quiet(1.0)], 3)


def test_the_assay_from_the_command_line_on_the_real_double_pendulum(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Two of the lab's runs without contact, two folds: a line per detector and joint, and
    the JSON scripts read; bad options get one clear line (also the named physics' detector,
    which needs two runs a fold to name anything)."""
    from transparency_ros.cli import main  # noqa: PLC0415

    runs = [str(SHARED / f"pendubot_clean_0{k}.csv.xz") for k in (1, 2)]
    common = [*runs, "--urdf", str(SHARED / "pendubot.urdf"), "--folds", "2"]
    assert main(["assay", *common, "--placements", "1", "--detectors", "calibrated,textbook"]) == 0
    out = capsys.readouterr()
    assert "sensitivity assay on 2 runs without contact" in out.out
    for line in ("calibrated Joint1: ", "calibrated Joint2: ", "textbook Joint1: "):
        assert line in out.out
    assert "calibrating on 1 runs" in out.err and "bisection 8/8" in out.err
    assert main(["assay", *common, "--placements", "1", "--detectors", "textbook", "--json"]) == 0
    import json  # noqa: PLC0415

    data = json.loads(capsys.readouterr().out)
    assert list(data["detectors"]) == ["textbook"] and data["folds"] == 2
    assert [s["joint"] for s in data["detectors"]["textbook"]] == ["Joint1", "Joint2"]
    for bad, message in (
        (["--folds", "3"], "2 run(s) for 3 folds"),
        (
            ["--detectors", "kalman"],
            "--detectors 'kalman': choose from calibrated, named, textbook",
        ),
        (["--widths", "0.05"], "--widths '0.05': two lengths in seconds"),
        (["--spacing", "0.1"], "pulse spacing 0.1 s"),
        ([], "the robot discrepancy tool needs at least two runs"),  # named: 1 run a fold
    ):
        assert main(["assay", *common, *bad]) == 2
        assert message in capsys.readouterr().err


def test_the_observer_on_the_named_physics_carries_each_effect_where_it_acts() -> None:
    """A chain whose motors act 4 ms late, with 0.1 N m more Coulomb friction on each joint
    than its URDF says, and its second link 0.3 kg heavier at the link's tip: given those
    effects (as the discrepancy tool's final model would hold them), the observer's residual
    without contact peaks at a tenth of the URDF's own at most; the effects' torques (the
    command delayed, the friction) and the payload (in the links' inertia) are each needed."""
    from transparency_ros.analysis.discrepancy.robot_effects import library  # noqa: PLC0415

    urdf = RobotModel.from_urdf(chain_urdf(2))
    truth_urdf = chain_urdf(2, friction=0.15).replace(
        '<link name="l1"><inertial><origin xyz="0 0 -0.1"/><mass value="0.5"/>',
        '<link name="l1"><inertial><origin xyz="0 0 -0.14"/><mass value="0.8"/>',
    )
    truth = RobotModel.from_urdf(truth_urdf)
    n = 4000
    stamps, q, v, command = simulate_chain(truth, np.zeros((n, 2)), delay_steps=4)
    run = JointRecording("run", stamps, urdf.joint_names, q, v, command)
    effects = {e.name: e for e in library(urdf.joint_names, np.full(2, 5.0), np.full(2, 5.0))}
    # the 0.3 kg the URDF lacks sits 0.2 m down link l1 (its centre of mass moves to 0.14 m)
    payload = effects["payload[j1]"]
    tip = np.linalg.lstsq(payload.frame, np.array([0.0, 0.0, -0.2]), rcond=None)[0]
    named = [
        (effects["command_delay"], np.array([0.0045])),
        (effects["coulomb_friction[j0]"], np.array([0.1])),
        (effects["coulomb_friction[j1]"], np.array([0.1])),
        (payload, np.r_[0.3, tip]),
    ]

    def peak(fitted: list) -> np.ndarray:  # what a threshold must clear, per joint
        residual = ra.named_detector(urdf, fitted, [run], 20.0).residual(run)[200:]
        return np.abs(residual).max(axis=0)

    everything = peak(named)
    assert np.all(everything < 0.1 * peak([]))
    for k in range(len(named)):  # each one is needed
        assert np.any(peak(named[:k] + named[k + 1 :]) > 2 * everything)
