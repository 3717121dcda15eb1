"""The estimator's momentum_observer method without ROS: commands by name and stamp, the
calibrated delay, and rejections that are counted, never raised past the node."""

from __future__ import annotations

import numpy as np
import pytest

from transparency_ros.core.estimator import (
    DetectorSettings,
    SampleRejectedError,
    SchmittDetector,
)
from transparency_ros.core.robot_calibration import SPEED_BANDS, Calibration
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.core.robot_pipeline import ObserverPipeline
from transparency_ros.synth.robots import chain_urdf


def pipeline(calibration: Calibration | None = None) -> ObserverPipeline:
    model = RobotModel.from_urdf(chain_urdf(2))
    detector = SchmittDetector(DetectorSettings(contact_onset=1.0, contact_release=0.5))
    return ObserverPipeline(model, 20.0, detector, calibration, threshold_nm=0.2)


def urdf_calibration(delay_s: float, offset: list[float]) -> Calibration:
    model = RobotModel.from_urdf(chain_urdf(2))
    pm = model.pin_model
    return Calibration(
        robot="chain2", joints=("j0", "j1"), gain_per_s=20.0, command_delay_s=delay_s,
        inertial=[list(pm.inertias[j].toDynamicParameters()) for j in (1, 2)],
        armature_kgm2=[0.0, 0.0], viscous_nms_per_rad=list(model.friction.viscous),
        coulomb_nm=list(model.friction.coulomb), offset_nm=offset,
        speed_bands_rad_s=list(SPEED_BANDS), thresholds_nm=[[1.0] * len(SPEED_BANDS)] * 2,
    )  # fmt: skip


def test_the_applied_torque_is_the_command_the_calibrated_delay_earlier_less_the_offset() -> None:
    p = pipeline(urdf_calibration(0.004, [0.1, -0.2]))
    for k in range(10):  # commands every ms, efforts k and 10 k
        p.command(["j1", "j0"], [], [], k * 1_000_000, efforts=[10.0 * k, float(k)])
    assert p._torque(9_000_000).tolist() == pytest.approx([5 - 0.1, 20 + 0.2])  # 50: limited to 20
    assert p._torque(3_000_000).tolist() == pytest.approx([0 - 0.1, 0 + 0.2])  # the first held
    uncalibrated = pipeline()
    uncalibrated.command(["j0"], [], [], 5, efforts=[1.5])
    assert uncalibrated._torque(10).tolist() == [1.5, 0.0]  # j1 passive


def test_bad_commands_and_samples_are_rejected_and_counted() -> None:
    p = pipeline()
    with pytest.raises(SampleRejectedError, match="no_effort"):
        p.command(["j0", "j1"], [0.1, 0.2], [], 0)
    with pytest.raises(SampleRejectedError, match="not_finite"):
        p.command(["j0"], [], [], 0, efforts=[float("nan")])
    p.sample(1_000, ["j1", "j0", "gripper"], [0.0, 0.0, 5.0], [0.0, 0.0, 0.0])
    with pytest.raises(SampleRejectedError, match=r"missing_joint: \['j1'\]"):
        p.sample(2_000, ["j0"], [0.0], [0.0])
    with pytest.raises(SampleRejectedError, match="length_mismatch"):
        p.sample(2_000, ["j0", "j1"], [0.0, 0.0], [])
    with pytest.raises(SampleRejectedError, match="not_finite"):
        p.sample(2_000, ["j0", "j1"], [0.0, np.nan], [0.0, 0.0])
    with pytest.raises(SampleRejectedError, match="stamp_not_increasing"):
        p.sample(1_000, ["j0", "j1"], [0.0, 0.0], [0.0, 0.0])
    estimates, _ = p.sample(2_000, ["j0", "j1"], [0.0, 0.0], [0.0, 0.0])
    assert [e.joint for e in estimates] == ["j0", "j1"] and p.samples == 2
    assert p.rejected == {
        "no_effort": 1, "not_finite": 2, "missing_joint": 1, "length_mismatch": 1,
        "stamp_not_increasing": 1,
    }  # fmt: skip


def test_each_sample_is_judged_against_the_calibrated_threshold_of_its_speed() -> None:
    cal = urdf_calibration(0.0, [0.0, 0.0])
    n = len(SPEED_BANDS)
    cal.thresholds_nm = [[0.1 * (b + 1) for b in range(n)], [1.0 * (b + 1) for b in range(n)]]
    p = pipeline(cal)
    p.command(["j0", "j1"], [], [], 0, efforts=[2.0, 1.0])  # a torque the states do not show
    speeds = [0.0, *(edge * 1.01 for edge in SPEED_BANDS[1:]), SPEED_BANDS[-1] * 10.0]
    p.sample(500_000, ["j0", "j1"], [0.0, 0.0], [0.0, 0.0])  # (the observer's first state)
    seen = set()
    for k, speed in enumerate(speeds):
        v = [speed * 0.6, speed * 0.8]  # the joints' speed norm is ``speed``
        estimates, _ = p.sample(1_000_000 * (k + 1), ["j0", "j1"], [0.0, 0.0], v)
        expected = cal.threshold(np.array([v]))[0]
        seen.add(float(expected[0]))
        for est, threshold in zip(estimates, expected, strict=True):
            assert est.torque_nm != 0.0
            assert est.error_rad == pytest.approx(abs(est.torque_nm) / threshold)  # the share
    assert len(seen) == n  # every band's threshold was used
