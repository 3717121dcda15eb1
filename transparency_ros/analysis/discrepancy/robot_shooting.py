"""A robot's model with what the discrepancy tool names, as a simulator and as a detector's
model: the URDF carrying the named effects, each where its physics acts, and the open-loop
error of short simulated windows (multiple shooting) on held-out runs.

The torque balance (:mod:`robot`) judges the model at the recorded states; a simulator is
judged on the motion it produces. Each window starts from the recorded state (positions, and
speeds from the positions' Savitzky-Golay derivative: a motor's reported speed has
single-sample glitches, 2 rad/s on the real pendubot, that would start a window wrong), runs the
model under the recorded command for ``WINDOW_S`` (RK4, one step per recorded sample, the command
held over it), and is compared with the recorded positions. Windows follow one another over the
whole run, as the 1-DoF tool's do.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.signal import savgol_filter

from transparency_ros.analysis.discrepancy.robot_effects import Context
from transparency_ros.analysis.robot_data import FloatArray, JointRecording
from transparency_ros.core.robot_calibration import effort_limit
from transparency_ros.core.robot_model import RobotModel

WINDOW_S = 0.2  # each simulated window
DIVERGED_RAD = math.pi  # a window further off than this at its end has left the motion
SPEED_POINTS = 15  # Savitzky-Golay window for the starting speeds (30 ms at 500 Hz)

Fitted = Sequence[tuple[Any, FloatArray]]  # (effect, parameters), as a report's ``fitted``


def carrying(base: RobotModel, fitted: Fitted) -> RobotModel:
    """``base`` with the inertial effects of ``fitted`` (payloads, a link's drift) in its
    links' inertial parameters, and the rotors' (armature) in its joints'."""
    import pinocchio as pin  # noqa: PLC0415

    pm = pin.Model(base.pin_model)
    nominal = np.concatenate([pm.inertias[j].toDynamicParameters() for j in range(1, base.dof + 1)])
    pi = nominal.copy()
    armature = np.array(pm.armature, dtype=float)
    for effect, p in fitted:
        change = effect.inertial(p, nominal)
        if change is not None:
            pi += change
        rotor = effect.armature(p)  # (a rotor's inertia: the joint's own, not a link's)
        if rotor is not None:
            armature[effect.joint] += rotor
    pm.armature = armature
    for j in range(base.dof):
        pm.inertias[j + 1] = pin.Inertia.FromDynamicParameters(pi[10 * j : 10 * j + 10])
    return RobotModel(pm, base.friction, f"{base.source} + named effects", list(base.notes))


def command_path(base: RobotModel, fitted: Fitted, t: FloatArray, command: FloatArray
                 ) -> FloatArray:  # fmt: skip
    """The torque reaching the joints from ``command`` (samples, joints) at stamps ``t`` [s]:
    within the effort limits, delayed, through the gains and saturations named. A negative
    delay (the positions recorded late) takes the command ahead: offline only."""
    limit = effort_limit(base)
    tau = np.clip(command, -limit, limit)
    delay = sum(effect.delay(p) for effect, p in fitted)
    if delay != 0.0:
        tau = np.stack([np.interp(t - delay, t, column) for column in tau.T], axis=1)
    for effect, p in fitted:
        if effect.stage == "command":
            tau = effect.command(tau, p)
    return np.asarray(tau, dtype=float)


def felt_torque(base: RobotModel, fitted: Fitted, q: FloatArray, v: FloatArray) -> FloatArray:
    """The torques the named friction, offsets and cogging add against the joints at states
    ``q``, ``v`` (samples, joints): what the model's side of the balance gains."""
    ctx = Context(
        v,
        np.zeros(v.shape),  # (the only effect using it, the armature, is in the model)
        np.tanh(v / base.friction.smoothing_rad_s),
        np.zeros((*q.shape, 0)),  # inertial effects are in the model (``carrying``), not here
        np.zeros(0),
        lambda j, n: np.stack([np.sin(n * q[:, j]), np.cos(n * q[:, j])], axis=1),
        lambda j, speed: (
            np.exp(-((v[:, j] / speed) ** 2)) * np.tanh(v[:, j] / base.friction.smoothing_rad_s)
        ),
    )
    out = np.zeros(q.shape)
    for effect, p in fitted:
        if not effect.rigid_body:  # (those are in the model, ``carrying``)
            extra = effect.torque(ctx, p)
            if extra is not None:
                out += extra
    return out


def window_errors(base: RobotModel, fitted: Fitted, runs: Sequence[JointRecording]
                  ) -> tuple[FloatArray, int, int]:  # fmt: skip
    """Per joint, the RMS of simulated minus recorded positions over every window of ``runs``
    [rad] (windows that diverge count at ``DIVERGED_RAD``), the windows and those diverged."""
    model = carrying(base, fitted)

    def rate(q: FloatArray, v: FloatArray, applied: FloatArray) -> FloatArray:
        felt = felt_torque(base, fitted, q[None], v[None])[0]
        return model.forward_dynamics(q, v, applied - felt)

    squares = np.zeros(base.dof)
    samples = windows = diverged = 0
    for rec in runs:
        t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
        step = float(np.median(np.diff(t)))
        points = SPEED_POINTS if t.size > SPEED_POINTS else (t.size // 2) * 2 - 1
        v0 = savgol_filter(rec.position, points, 3, deriv=1, delta=step, axis=0)
        tau = command_path(base, fitted, t, rec.torque)
        length = max(2, round(WINDOW_S / step))
        for k in range(0, t.size - length, length):
            span = slice(k, k + length + 1)
            error, ok = _window(rate, (rec.position[k], v0[k]), tau[span], rec.position[span],
                                t[span])  # fmt: skip
            squares += np.sum(error**2, axis=0)
            samples += error.shape[0]
            windows += 1
            diverged += not ok
    if samples == 0:  # runs shorter than a window
        return np.full(base.dof, math.nan), 0, 0
    return np.sqrt(squares / samples), windows, diverged


def _window(rate: Any, start: tuple[FloatArray, FloatArray], tau: FloatArray,
            recorded: FloatArray, t: FloatArray) -> tuple[FloatArray, bool]:  # fmt: skip
    """One window: RK4 from ``start`` (q, v) under ``tau`` held over each step, its positions'
    error against ``recorded`` at the window's samples but the last, and whether it stayed
    within ``DIVERGED_RAD``."""
    q, v = start[0].copy(), start[1].copy()
    length = t.size - 1
    error = np.zeros((length, q.size))
    for k in range(length):
        error[k] = q - recorded[k]
        h, u = t[k + 1] - t[k], tau[k]
        a1 = rate(q, v, u)
        v2 = v + 0.5 * h * a1
        a2 = rate(q + 0.5 * h * v, v2, u)
        v3 = v + 0.5 * h * a2
        a3 = rate(q + 0.5 * h * v2, v3, u)
        v4 = v + h * a3
        a4 = rate(q + h * v3, v4, u)
        q = q + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
        v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        if not (np.all(np.isfinite(q)) and np.all(np.abs(q - recorded[k + 1]) < DIVERGED_RAD)):
            error[k + 1 :] = DIVERGED_RAD
            return error, False
    return error, True
