"""Calibration of a robot's contact detector from recordings without contact.

The model is always wrong (the double pendulum's URDF gives its links' inertias about the wrong
point; no URDF has the actuators' delay). From runs in which nothing touched the robot, this
learns what the model misses and stores it as a YAML the detector loads:

* the **command delay**: the applied torque is the command some milliseconds earlier (the
  motor's current loop and the bus), searched on a grid by the fit below;
* the **rigid-body parameters** of every body, each joint's **armature** (the rotor's reflected
  inertia), **viscous and Coulomb friction** and a **torque offset**, by least squares on the
  joint-torque regressor: the dynamics are linear in them, tau = Y(q, q', q'') pi, so one solve
  is exact (the discrepancy tool's fitter, which simulates windows of a 1-DoF model, is not
  needed here). Offline, q' and q'' come from a Savitzky-Golay fit of the positions. The fit is
  drawn weakly towards the URDF's values (ridge). It is a fit of the torque balance, not a
  physical identification: the share of configurations where its mass matrix is positive
  definite is stored with it (the observer never inverts M);
* **thresholds that depend on the motion**: the observer's residual on the calibration runs,
  with the calibrated model, grows with speed; per joint and speed band, the largest residual
  seen times a margin, never lower at a higher speed. Above the fastest speed calibrated the
  threshold is infinite: the detector does not judge motion it has not seen without contact
  (the evaluation reports how much of a run that is).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.signal import savgol_filter

from transparency_ros.analysis.robot_data import FloatArray, JointRecording
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.estimator import DetectorSettings, EventKind, SchmittDetector
from transparency_ros.core.robot_calibration import (
    SPEED_BANDS,
    Calibration,
    banded_thresholds,
    effort_limit,
)
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.core.robot_pipeline import ObserverPipeline

DELAYS_S = tuple(k * 1e-3 for k in range(0, 21))  # command delays tried
GRID_S = 0.002  # the positions are resampled on this grid for the regressor
SMOOTHING_POINTS = 31  # Savitzky-Golay window (62 ms) for q', q'' and the torque alike
MARGIN = 1.2  # thresholds: the largest calibration residual times this
RIDGE = 1e-3  # drawn towards the URDF's values, relative


def run_pipeline(
    base: RobotModel, cal: Calibration, recording: JointRecording
) -> tuple[FloatArray, list[list[float]]]:
    """The estimator node's pipeline (:class:`ObserverPipeline`) over ``recording`` (in the
    model's joint order), each sample's command given before it: the residuals (samples,
    joints) and each joint's contact onsets [s]. Offline results are then the node's."""
    detector = SchmittDetector(DetectorSettings(contact_onset=1.0, contact_release=0.5))
    pipeline = ObserverPipeline(base, cal.gain_per_s, detector, cal)
    names = list(recording.joints)
    residual = np.empty(recording.position.shape)
    onsets: list[list[float]] = [[] for _ in names]
    for k, stamp in enumerate(recording.stamps_ns.tolist()):
        pipeline.command(names, [], [], stamp, efforts=recording.torque[k].tolist())
        estimates, events = pipeline.sample(
            stamp, names, recording.position[k].tolist(), recording.velocity[k].tolist()
        )
        residual[k] = [e.torque_nm for e in estimates]
        for event in events:
            if event.kind is EventKind.CONTACT_ONSET:
                onsets[names.index(event.joint)].append(event.stamp_ns * 1e-9)
    return residual, onsets


def applied(recording: JointRecording, delay_s: float, limit: FloatArray) -> FloatArray:
    """The command limited to the joints' effort limits, ``delay_s`` earlier."""
    t = recording.stamps_ns * 1e-9
    tau = np.clip(recording.torque, -limit, limit)
    if delay_s == 0:
        return tau
    return np.stack([np.interp(t - delay_s, t, tau[:, j]) for j in range(tau.shape[1])], axis=1)


def calibrate(
    model: RobotModel,
    recordings: Sequence[JointRecording],
    gain_per_s: float,
    progress: Any = None,
) -> Calibration:
    """Calibrate ``model`` on ``recordings`` (no contact in them)."""
    import pinocchio as pin  # noqa: PLC0415

    if not recordings:
        raise ConfigError("calibration needs at least one recording without contact")
    recordings = [r.reordered(model.index(r.joints, where=r.name), model.joint_names)
                  for r in recordings]  # fmt: skip
    pm = model.pin_model
    n = model.dof
    limit = effort_limit(model)
    prior = np.concatenate(
        [
            np.concatenate([pm.inertias[j].toDynamicParameters() for j in range(1, n + 1)]),
            np.zeros(n),  # armature (added to the URDF's, which has none here)
            model.friction.viscous,
            model.friction.coulomb,
            np.zeros(n),  # offset
        ]
    )
    rows, grids = [], []
    for rec in recordings:
        q, v, a, grid = _smoothed(rec)
        data = pm.createData()
        # (pinocchio gives a one-joint robot's (1, 10) regressor as a vector: reshaped)
        y = np.array([
            np.reshape(pin.computeJointTorqueRegressor(pm, data, *x), (n, -1))
            for x in zip(q, v, a, strict=True)
        ])  # fmt: skip
        eye = np.eye(n)
        extra = np.concatenate(
            [
                eye[None] * a[:, None, :],
                eye[None] * v[:, None, :],
                eye[None] * np.tanh(v / model.friction.smoothing_rad_s)[:, None, :],
                np.broadcast_to(eye, (len(grid), n, n)),
            ],
            axis=2,
        )
        rows.append(np.concatenate([y, extra], axis=2).reshape(-1, prior.size))
        grids.append(grid)
        if progress:
            progress(f"regressor of {rec.name}: {len(grid)} samples")
    x = np.concatenate(rows)
    visited = np.concatenate(
        [rec.position[:: max(1, len(rec.position) // 100)] for rec in recordings]
    )
    best: tuple[float, float, FloatArray] | None = None
    for delay in DELAYS_S:
        target = np.concatenate(
            [_target(rec, g, delay, limit) for rec, g in zip(recordings, grids, strict=True)]
        )
        solution = _ridge(x, target, prior)
        rms = float(np.sqrt(np.mean((target - x @ solution) ** 2)))
        if best is None or rms < best[0]:
            best = (rms, delay, solution)
    assert best is not None
    rms, delay, solution = best
    m = 10 * n
    cal = Calibration(
        robot=str(pm.name),
        joints=tuple(model.joint_names),
        gain_per_s=gain_per_s,
        command_delay_s=delay,
        inertial=solution[:m].reshape(n, 10).tolist(),
        armature_kgm2=solution[m : m + n].tolist(),
        viscous_nms_per_rad=solution[m + n : m + 2 * n].tolist(),
        coulomb_nm=solution[m + 2 * n : m + 3 * n].tolist(),
        offset_nm=solution[m + 3 * n :].tolist(),
        speed_bands_rad_s=list(SPEED_BANDS),
        thresholds_nm=[[0.0] * len(SPEED_BANDS) for _ in range(n)],
        calibrated_on=[r.name for r in recordings],
        torque_rms_nm=rms,
    )
    if progress:
        progress(f"command delay {delay * 1e3:.0f} ms, torque residual {rms:.3f} N m RMS")
    cal.thresholds_nm = _thresholds(cal, model, recordings)
    cal.mass_matrix_positive_share = positive_share(cal, model, visited)
    return cal


def _target(rec: JointRecording, grid: FloatArray, delay_s: float, limit: FloatArray
            ) -> FloatArray:  # fmt: skip
    """The applied torque on ``grid``, low-passed as the positions are (the same
    Savitzky-Golay fit, over the same neighbours), so that both sides of tau = Y pi see the same
    band: noise in q'' no longer pulls the inertias to 0. Flattened (samples x joints)."""
    h = SMOOTHING_POINTS // 2
    wide = np.r_[
        grid[0] - GRID_S * np.arange(h, 0, -1), grid, grid[-1] + GRID_S * np.arange(1, h + 1)
    ]
    t = rec.stamps_ns * 1e-9
    tau = np.stack([np.interp(wide, t, col) for col in applied(rec, delay_s, limit).T], axis=1)
    return np.asarray(
        savgol_filter(tau, SMOOTHING_POINTS, 3, axis=0)[h:-h], dtype=np.float64
    ).reshape(-1)


def _smoothed(rec: JointRecording) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Positions on a uniform grid, with q' and q'' from a Savitzky-Golay fit."""
    t = rec.stamps_ns * 1e-9
    grid = np.arange(t[0], t[-1], GRID_S)
    if grid.size < 3 * SMOOTHING_POINTS:
        raise ConfigError(f"{rec.name}: too short to calibrate on ({t[-1] - t[0]:.2f} s)")
    q = np.stack([np.interp(grid, t, col) for col in rec.position.T], axis=1)
    v = savgol_filter(q, SMOOTHING_POINTS, 3, deriv=1, delta=GRID_S, axis=0)
    a = savgol_filter(q, SMOOTHING_POINTS, 3, deriv=2, delta=GRID_S, axis=0)
    inner = slice(SMOOTHING_POINTS // 2, -(SMOOTHING_POINTS // 2))  # the fit is poor at the ends
    return q[inner], v[inner], a[inner], grid[inner]


def _ridge(x: FloatArray, target: FloatArray, prior: FloatArray) -> FloatArray:
    """Least squares drawn weakly towards ``prior``; a parameter the motion does not excite (a
    planar robot's other axes) stays at its prior."""
    rms = np.sqrt(np.mean(x**2, axis=0))
    reg = np.diag(RIDGE * math.sqrt(x.shape[0]) * np.maximum(rms, 1e-3 * rms.max()))
    solution = np.linalg.lstsq(np.r_[x, reg], np.r_[target, reg @ prior], rcond=None)[0]
    return np.asarray(solution, dtype=np.float64)


def positive_share(cal: Calibration, base: RobotModel, visited: FloatArray) -> float:
    """The share of ``visited`` configurations where the calibrated M(q) is positive definite.
    The observer never inverts M, so a fit that is not everywhere (a negative armature
    standing in for the URDF's too large link inertias) still detects; it is no physical
    robot to simulate, which the calibration file says."""
    model = cal.model(base)
    return float(np.mean([np.linalg.eigvalsh(model.mass_matrix(q))[0] > 0 for q in visited]))


def _thresholds(
    cal: Calibration, base: RobotModel, recordings: Sequence[JointRecording]
) -> list[list[float]]:
    """Per joint and speed band: the largest calibration residual times MARGIN, carried up to
    the faster bands (never lower at a higher speed)."""
    blind = replace(cal, thresholds_nm=[[math.inf] * len(cal.speed_bands_rad_s)] * base.dof)
    residuals = [run_pipeline(base, blind, rec)[0] for rec in recordings]  # (no events)
    velocities = [rec.velocity for rec in recordings]
    return banded_thresholds(residuals, velocities, cal.speed_bands_rad_s, MARGIN)
