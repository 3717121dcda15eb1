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

import numpy as np
import pysindy as ps

from transparency_ros.analysis.discrepancy.discover import split_trials
from transparency_ros.analysis.discrepancy.model import (
    NominalModel,
    Trial,
    make_windows,
    smooth_derivatives,
)

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
