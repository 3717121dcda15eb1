"""PySINDy as the peer of the discrepancy tool: the best library we can give it for a 1-DoF
torque-driven joint, and a reading of its terms as effect names.

Library (pysindy GeneralizedLibrary over [q, q', tau]): sin(k q), cos(k q) for k = 1..24 (gravity,
payload, cogging), q' and sign(q') (viscous and Coulomb friction), 1 and tau (offset, inertia).
STLSQ on the accelerations (smoothed derivatives of q) of the fitting trials; the threshold is
chosen among a few by the held-out windowed simulation error, as the tool's effects are.

Reading: identified coefficients times the nominal inertia are torques, compared with what the
nominal model implies: a constant -> torque_offset; sin/cos(k q) with k >= 2 -> cogging; the
k = 1 pair off the nominal gravity by more than 0.1 N m -> payload_gravity; the q', sign(q') or
tau coefficient off by more than 20 % -> parameter_drift. Stiction, saturation and delay have no
term in such a library: SINDy cannot name them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pysindy as ps

from transparency_ros.analysis.discrepancy.model import (
    NominalModel,
    Trial,
    make_windows,
    smooth_derivatives,
)
from transparency_ros.analysis.discrepancy.problem import split_trials

FREQUENCIES = 24
THRESHOLDS = (0.1, 0.3, 1.0, 3.0)


def _features(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    k = np.arange(1, FREQUENCIES + 1)
    return np.column_stack([
        np.ones_like(q), tau, qd, np.sign(qd),
        np.sin(np.outer(q, k)), np.cos(np.outer(q, k)),
    ])  # fmt: skip


NAMES = (
    ["1", "tau", "qd", "sign_qd"]
    + [f"sin{k}q" for k in range(1, FREQUENCIES + 1)]
    + [f"cos{k}q" for k in range(1, FREQUENCIES + 1)]
)


def _library() -> ps.GeneralizedLibrary:
    fourier = ps.FourierLibrary(n_frequencies=FREQUENCIES)
    # pysindy inspects __code__: plain functions, not numpy ufuncs
    friction = ps.CustomLibrary(library_functions=[lambda x: x, lambda x: np.sign(x)])  # noqa: PLW0108
    drive = ps.PolynomialLibrary(degree=1, include_bias=True)
    return ps.GeneralizedLibrary([fourier, friction, drive], inputs_per_library=[[0], [1], [2]])


def _smooth(trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    return smooth_derivatives(trial, 0.02, 3)  # the derivatives the tool's residual uses


def _coefficients(model: ps.SINDy) -> np.ndarray:
    """The q'' row, reordered to NAMES (1, tau, qd, sign, sin k q, cos k q)."""
    names = model.feature_library.get_feature_names(["q", "qd", "tau"])
    row = model.coefficients()[1]
    lookup = dict(zip(names, row, strict=True))

    def get(*candidates: str) -> float:
        for c in candidates:
            if c in lookup:
                return float(lookup[c])
        return 0.0

    out = [get("1"), get("tau"), get("f0(qd)"), get("f1(qd)")]
    out += [get(f"sin({k} q)", f"sin({k}q)") for k in range(1, FREQUENCIES + 1)]
    out += [get(f"cos({k} q)", f"cos({k}q)") for k in range(1, FREQUENCIES + 1)]
    return np.array(out)


def _simulate(coef: np.ndarray, trials: Sequence[Trial], window_s: float) -> float:
    w = make_windows(trials, window_s)
    q = w.q[:, 0].copy()
    qd = np.array(w.extra["qd0"], dtype=float)
    err = [np.zeros_like(q)]
    for k in range(1, w.q.shape[1]):
        qdd = np.clip(_features(q, qd, w.tau[:, k - 1]) @ coef, -1e4, 1e4)
        qd = qd + qdd * w.dt
        q = q + qd * w.dt
        err.append(q - w.q[:, k])
    return float(np.sqrt(np.mean(np.square(err))))


def run_sindy(model: NominalModel, trials: Sequence[Trial], window_s: float = 0.1
              ) -> tuple[list[str], float, float]:  # fmt: skip
    """(effect names read from the terms, held-out RMSE of the best fit, of the nominal)."""
    fit, held = split_trials(trials)
    xs, dxs, us = [], [], []
    for tr in fit:
        qd, qdd = _smooth(tr)
        xs.append(np.column_stack([tr.q, qd]))
        dxs.append(np.column_stack([qd, qdd]))
        us.append(tr.tau[:, None])
    j = model.inertia_kgm2
    nominal = np.zeros(len(NAMES))
    nominal[1], nominal[2], nominal[3] = (
        1 / j,
        -model.viscous_nms_per_rad / j,
        -model.coulomb_nm / j,
    )
    nominal[4] = -model.gravity_nm / j
    nominal_rmse = _simulate(nominal, held, window_s)
    best: tuple[float, np.ndarray] | None = None
    for threshold in THRESHOLDS:
        sindy = ps.SINDy(
            feature_library=_library(), optimizer=ps.STLSQ(threshold=threshold, alpha=0.05)
        )
        sindy.fit(xs, t=fit[0].dt, x_dot=dxs, u=us)
        coef = _coefficients(sindy)
        rmse = _simulate(coef, held, window_s)
        if math.isfinite(rmse) and (best is None or rmse < best[0]):
            best = (rmse, coef)
    assert best is not None
    rmse, coef = best
    torque = coef * j  # torque-equivalent terms
    nominal_t = nominal * j
    found: list[str] = []
    if abs(torque[0]) > 0.05:
        found.append("torque_offset")
    sin, cos = torque[4 : 4 + FREQUENCIES], torque[4 + FREQUENCIES :]
    if np.any(np.hypot(sin[1:], cos[1:]) > 0.05):
        found.append("cogging")
    if math.hypot(sin[0] - nominal_t[4], cos[0]) > 0.1:
        found.append("payload_gravity")
    ratios = [torque[i] / nominal_t[i] for i in (1, 2, 3) if nominal_t[i] != 0]
    if any(abs(r - 1.0) > 0.2 for r in ratios):
        found.append("parameter_drift")
    return found, rmse, nominal_rmse


# ----------------------------------------------------------------------------- drop tests

DROP_NAMES = ("1", "q", "qd", "sign_qd", "cos_q")
SETTLE_S = 0.005  # after the load cell falls back below threshold


def _drop_features(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    return np.column_stack([np.ones_like(q), q, qd, np.sign(qd), np.cos(q)])


def _post_impact(trial: Any) -> tuple[np.ndarray, np.ndarray]:
    """Encoder (t, q) from just after the first impact to the end of the impact piece."""
    sel = (trial.t_q >= trial.contact_end_s + SETTLE_S) & (trial.t_q <= trial.end_s)
    return trial.t_q[sel], trial.q[sel]


def _drop_simulate(coef: np.ndarray, trials: Sequence[Any]) -> float:
    """Encoder RMSE of the ODE q'' = coef . features from each trial's post-impact state."""
    err = []
    for trial in trials:
        t, q_rec = _post_impact(trial)
        if t.size < 20:
            continue
        qd0 = float(np.polyfit(t[:7] - t[0], q_rec[:7], 2)[1])
        dt = 1e-4
        grid = np.arange(t[0], t[-1], dt)
        q, qd, out = float(q_rec[0]), qd0, np.empty(grid.size)
        for k in range(grid.size):
            out[k] = q
            qdd = float(_drop_features(np.array([q]), np.array([qd]))[0] @ coef)
            qd = float(np.clip(qd + qdd * dt, -1e3, 1e3))
            q += qd * dt
        err.append(np.interp(t, grid, out) - q_rec)
    return float(np.sqrt(np.mean(np.concatenate(err) ** 2))) if err else math.nan


def run_sindy_drop(problem: Any) -> tuple[list[str], float, float]:
    """PySINDy on the arm's motion after the first impact (the part of a drop an ODE in the
    arm angle can describe): library 1, q, q', sign(q'), cos q; the nominal is eq. (2) with the
    shuttle on the arm. Reading, as torques (coefficient times J = J_r + J_arm + m_s r^2): a
    constant above 0.05 N m -> torque_offset; cos q above 0.1 N m -> payload_gravity; q, q' or
    sign(q') off the nominal by more than 20 % -> parameter_drift. Impacts, rebounds, backlash,
    compliance, rail friction, delay and quantization have no term in such a library."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    a = problem.actuator
    first = problem.fit_trials[0]
    j = (
        problem.model.reflected_inertia_kgm2[a]
        + first.arm_inertia_kgm2
        + first.mass_kg * first.arm_m**2
    )
    nominal = np.array([
        0.0, -first.k_s / j, -problem.model.viscous_nms_per_rad[a] / j,
        -problem.model.coulomb_nm[a] / j, 0.0,
    ])  # fmt: skip
    xs, dxs = [], []
    for trial in problem.fit_trials:
        t, q = _post_impact(trial)
        if t.size < 31:
            continue
        dt = float(np.median(np.diff(t)))
        grid = np.arange(t[0], t[-1], dt)
        qg = np.interp(grid, t, q)
        qd = savgol_filter(qg, 21, 3, deriv=1, delta=dt)
        qdd = savgol_filter(qg, 21, 3, deriv=2, delta=dt)
        xs.append(np.column_stack([qg, qd]))
        dxs.append(np.column_stack([qd, qdd]))
    nominal_rmse = _drop_simulate(nominal, problem.held_trials)
    if not xs:
        return [], nominal_rmse, nominal_rmse
    best: tuple[float, np.ndarray] | None = None

    def library() -> ps.GeneralizedLibrary:
        # features in DROP_NAMES order: 1, q, q', sign(q'), cos q
        return ps.GeneralizedLibrary(
            [
                ps.PolynomialLibrary(degree=0),
                ps.CustomLibrary(library_functions=[lambda x: x]),
                ps.CustomLibrary(library_functions=[lambda x: x, lambda x: np.sign(x)]),  # noqa: PLW0108
                ps.CustomLibrary(library_functions=[lambda x: np.cos(x)]),  # noqa: PLW0108
            ],
            inputs_per_library=[[0], [0], [1], [0]],
        )

    for threshold in THRESHOLDS:
        sindy = ps.SINDy(
            feature_library=library(),
            optimizer=ps.STLSQ(threshold=threshold, alpha=0.05),
        )
        sindy.fit(xs, t=dt, x_dot=dxs)
        coef = np.asarray(sindy.coefficients()[1], dtype=float)
        rmse = _drop_simulate(coef, problem.held_trials)
        if math.isfinite(rmse) and (best is None or rmse < best[0]):
            best = (rmse, coef)
    if best is None:
        return [], nominal_rmse, nominal_rmse
    rmse, coef = best
    torque, nominal_t = coef * j, nominal * j
    found: list[str] = []
    if abs(torque[0]) > 0.05:
        found.append("torque_offset")
    if abs(torque[4]) > 0.1:
        found.append("payload_gravity")
    if any(abs(torque[i] / nominal_t[i] - 1.0) > 0.2 for i in (1, 2, 3) if nominal_t[i] != 0):
        found.append("parameter_drift")
    return found, rmse, nominal_rmse
