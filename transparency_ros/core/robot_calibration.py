"""A robot detector's calibration as the estimator loads it: what the model misses, learnt
from runs without contact (``transparency calibrate``, :mod:`transparency_ros.analysis.
robot_calibration`), stored as YAML: the command delay, every body's rigid-body parameters,
each joint's armature, friction and torque offset, and thresholds per band of speed."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import yaml

from transparency_ros.core.errors import ConfigError
from transparency_ros.core.robot_model import JointFriction, RobotModel

FloatArray = npt.NDArray[np.float64]
SPEED_BANDS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 18.0, 22.0, 26.0, 32.0)  # |q'| [rad/s]


def effort_limit(model: RobotModel) -> FloatArray:
    """Each joint's effort limit from the URDF (inf where it gives none)."""
    limit = np.array(model.pin_model.effortLimit, dtype=float)
    return np.where(limit > 0, limit, np.inf)


def speed_band(bands: Sequence[float] | FloatArray, velocity: FloatArray) -> npt.NDArray[np.intp]:
    """Per sample, the band of ``bands`` (their lower edges [rad/s]) its speed (the norm of
    the joints' velocities) falls in."""
    speed = np.linalg.norm(np.atleast_2d(velocity), axis=1)
    band = np.searchsorted(bands, speed, side="right") - 1
    out: npt.NDArray[np.intp] = np.clip(band, 0, len(bands) - 1)
    return out


def at_speed(thresholds_nm: Sequence[Sequence[float]], bands: Sequence[float],
             velocity: FloatArray) -> FloatArray:  # fmt: skip
    """Per sample and joint, the threshold of ``thresholds_nm`` (per joint, per band) at the
    sample's speed, (samples, joints)."""
    out: FloatArray = np.asarray(thresholds_nm, dtype=float).T[speed_band(bands, velocity)]
    return out


def banded_thresholds(residuals: Sequence[FloatArray], velocities: Sequence[FloatArray],
                      bands: Sequence[float], margin: float) -> list[list[float]]:  # fmt: skip
    """Per joint and speed band: the largest of ``residuals`` (runs without contact, each
    (samples, joints) with its ``velocities``) in the band times ``margin``, carried up to the
    faster bands (never lower at a higher speed); infinite above the fastest band seen (a
    detector does not judge motion it has not seen without contact)."""
    dof = residuals[0].shape[1]
    top = np.zeros((dof, len(bands)))
    seen = np.zeros(len(bands), dtype=bool)
    for r, v in zip(residuals, velocities, strict=True):
        band = speed_band(bands, v)
        for b in np.unique(band):
            top[:, b] = np.maximum(top[:, b], np.abs(r[band == b]).max(axis=0))
            seen[b] = True
    top = np.maximum.accumulate(top, axis=1)
    top[:, np.arange(len(bands)) > np.flatnonzero(seen).max()] = np.inf
    out: list[list[float]] = (margin * top).tolist()
    return out


@dataclass
class Calibration:
    """What the model misses, learnt from runs without contact."""

    robot: str
    joints: tuple[str, ...]
    gain_per_s: float
    command_delay_s: float
    inertial: list[list[float]]  # per joint, its body's 10 dynamic parameters (Pinocchio's)
    armature_kgm2: list[float]
    viscous_nms_per_rad: list[float]
    coulomb_nm: list[float]
    offset_nm: list[float]
    speed_bands_rad_s: list[float]
    thresholds_nm: list[list[float]]  # per joint, per speed band
    calibrated_on: list[str] = field(default_factory=list)
    torque_rms_nm: float = math.nan  # of the regression, on the calibration runs
    mass_matrix_positive_share: float = math.nan  # of the calibration runs' configurations

    def model(self, base: RobotModel) -> RobotModel:
        """``base`` (the URDF's model) with the calibrated values."""
        if tuple(base.joint_names) != self.joints:
            raise ConfigError(
                f"calibration for robot {self.robot!r} with joints {list(self.joints)}; the "
                f"model {base.source} has {list(base.joint_names)}: a calibration from another "
                "robot"
            )
        import pinocchio as pin  # noqa: PLC0415

        pm = pin.Model(base.pin_model)
        for j, params in enumerate(self.inertial):
            pm.inertias[j + 1] = pin.Inertia.FromDynamicParameters(np.array(params))
        pm.armature = np.array(self.armature_kgm2)
        friction = JointFriction(np.array(self.viscous_nms_per_rad), np.array(self.coulomb_nm))
        return RobotModel(pm, friction, f"{base.source} + calibration", list(base.notes))

    def threshold(self, velocity: FloatArray) -> FloatArray:
        """Per sample and joint, the threshold at that sample's speed, (samples, joints)."""
        return at_speed(self.thresholds_nm, self.speed_bands_rad_s, velocity)

    def save(self, path: str | Path) -> None:
        data = {k: v for k, v in vars(self).items()}
        data["joints"] = list(self.joints)
        Path(path).write_text(yaml.safe_dump(data, sort_keys=False))

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        p = Path(path)
        try:
            data = yaml.safe_load(p.read_text())
            data["joints"] = tuple(data["joints"])
            cal = cls(**data)
        except (OSError, yaml.YAMLError, TypeError, KeyError) as err:
            raise ConfigError(f"{p}: not a calibration file: {err}") from err
        n = len(cal.joints)
        for key in ("inertial", "armature_kgm2", "viscous_nms_per_rad", "coulomb_nm",
                    "offset_nm", "thresholds_nm"):  # fmt: skip
            if len(getattr(cal, key)) != n:
                raise ConfigError(f"{p}: {key} has {len(getattr(cal, key))} entries, not {n}")
        return cal
