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
