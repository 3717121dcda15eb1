"""The load cell while the shuttle rides the arm: what the encoder cannot show.

Once the shuttle rides the arm, the load cell reads what accelerates it, F = m_s (g + y'')
(plus the rail's friction, f sgn y'), so a torque on the arm of a few hundredths of a newton
metre moves it by tenths of a newton: tens of times its noise in 1 ms means. The encoder sees
the same torque only through what it does to the angle within a short swing, which may be
less than a count. On the zoo's development campaigns (seeds 9800-9999) a cogging no
kinematic fit could find left the ride's load-cell residual at 4-10x its noise after the
shuttle's weight, and the true cogging brought it back to 0.8-1.9x (4.7x in one whose
contact law the model lacks); effect-free campaigns stood at 0.6-3.1x (one at 7x).

:class:`ForceView` is a drop-test problem seen through this residual, for the loop's last
stage (``Discoverer``: after the kinematic search, the effects it did not name are tried on
the load cell, the effects found held). The residual is the measured minus the simulated
force in 1 ms bins from ``FORCE_LEAD_S`` after contact (the strike's own pulse is the contact
law's, which the tool does not model) to the trial's end, each in units of its uncertainty:
the load cell's noise in 1 ms means (from the fall, where it reads nothing), and where the
force changes fast, a timing error of ``TIMING_S`` times its slope (the load cell's filter and
its transport against the model's instants: at 4 ms after a stiff strike the force falls by
20 N a millisecond).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.drop_effects import DropEffect
from transparency_ros.analysis.discrepancy.drop_physics import STEP_S, DropPhysics, stack_physics
from transparency_ros.analysis.discrepancy.drop_trials import DropTrial
from transparency_ros.analysis.discrepancy.model import GRAVITY, FloatArray

BIN_S = 1e-3  # the load cell compared in means over this long
FORCE_LEAD_S = 0.003  # from this long after contact
TIMING_S = 0.3e-3  # the load cell's timing against the model's, as an uncertainty
NOISE_WINDOW_S = 0.04  # its noise from this stretch of the fall, ending 5 ms before contact
FORCE_SIGNIFICANT = 3.5  # held-out RMS (in uncertainties) above which structure is left
KINEMATICS_KEPT = 1.05  # an effect named here may raise the kinematic held-out RMSE this much
# where the shuttle leaves the arm and strikes it again (a rebound, a chatter), the ride is
# compared from this long after its last flight on: each strike's pulse and ring are the
# contact law's, as the first one's are (FORCE_LEAD_S), and a model whose bounces differ in
# time by a millisecond misses them by hundreds of uncertainties. zoo_13285 (a rebound, a
# backlash, a cogging): the re-strikes left 44-128 uncertainties in bins the settled ride
# kept at 1-6, which the hidden cogging took to 0.3-0.8; it was not named
SETTLE_S = 0.010
FLIGHT_SHARE = 0.5  # a bin reading less than this share of the shuttle's weight: in flight


class _Bins:
    """The compared 1 ms bins of some trials: measured means and uncertainties, and where
    each bin starts on the simulator's grid."""

    def __init__(self, trials: Sequence[DropTrial], sim: Any) -> None:
        self.trials = list(trials)
        self.sim = sim
        self.start: list[npt.NDArray[np.int64]] = []  # first simulator step of each bin
        self.times: list[FloatArray] = []  # absolute start of each bin [s]
        self.measured: list[FloatArray] = []
        self.sigma: list[FloatArray] = []
        per = round(BIN_S / STEP_S)
        for t in self.trials:
            noise = _noise(t)
            edges = np.arange(t.contact_s + FORCE_LEAD_S, t.end_s - BIN_S, BIN_S)
            if noise is None or edges.size < 2:
                edges = edges[:0]
            lo = np.searchsorted(t.t_h, edges)
            hi = np.searchsorted(t.t_h, edges + BIN_S)
            sums = np.r_[0.0, np.cumsum(t.force)]
            measured = (sums[hi] - sums[lo]) / np.maximum(hi - lo, 1)
            slope = np.abs(np.gradient(measured, BIN_S)) if measured.size > 1 else measured
            self.times.append(edges)
            self.start.append(np.round((edges - t.start_s) / STEP_S).astype(np.int64))
            self.measured.append(measured)
            self.sigma.append(np.sqrt((noise or 0.0) ** 2 + (TIMING_S * slope) ** 2))
        self.per = per
        # the bins compared (settle): all until the view is started on a model
        self.kept = [np.ones(m.size, dtype=bool) for m in self.measured]

    @property
    def size(self) -> int:
        return int(sum(int(k.sum()) for k in self.kept))

    def kept_times(self) -> list[FloatArray]:
        return [t[k] for t, k in zip(self.times, self.kept, strict=True)]

    def settle(self, physics: DropPhysics) -> None:
        """Keep the bins from SETTLE_S after the last flight of the shuttle (a bin reading
        less than FLIGHT_SHARE of its weight) that the recording or the model ``physics``
        shows, every bin of a trial where neither shows one."""
        model = self._model_bins([physics])[0]
        for i, t in enumerate(self.trials):
            light = FLIGHT_SHARE * t.mass_kg * GRAVITY
            flight = (self.measured[i] < light) | (model[i] < light)
            last = self.times[i][flight].max() if flight.any() else -np.inf
            self.kept[i] = self.times[i] >= last + BIN_S + SETTLE_S

    def error_many(self, physics: Sequence[DropPhysics]) -> list[FloatArray]:
        out = []
        for model in self._model_bins(physics):
            parts = [
                ((m - f) / s)[k]
                for m, f, s, k in zip(self.measured, model, self.sigma, self.kept, strict=True)
            ]
            out.append(np.concatenate(parts) if parts else np.zeros(0))
        return out

    def _model_bins(self, physics: Sequence[DropPhysics]) -> list[list[FloatArray]]:
        """The model's load cell in each trial's bins, for each physics."""
        n = len(self.trials)
        ph = stack_physics(physics, n)
        _t, _q, y = self.sim.run(ph, len(physics))
        speed = np.gradient(y, STEP_S, axis=1)
        acc = np.gradient(speed, STEP_S, axis=1)
        rail = np.broadcast_to(np.asarray(ph.rail_friction_n, dtype=float), (y.shape[0],))
        out = []
        for j in range(len(physics)):
            parts = []
            for i, t in enumerate(self.trials):
                row = j * n + i
                force = t.mass_kg * (GRAVITY + acc[row]) + rail[row] * np.sign(speed[row])
                sums = np.r_[0.0, np.cumsum(force)]
                lo = np.minimum(self.start[i], force.size - 1)
                hi = np.minimum(lo + self.per, force.size)
                parts.append((sums[hi] - sums[lo]) / np.maximum(hi - lo, 1))
            out.append(parts)
        return out


def _noise(trial: DropTrial) -> float | None:
    """The load cell's noise in 1 ms means, from the fall (None: too little of it recorded, or
    no variation in it)."""
    end = trial.contact_s - 0.005
    sel = (trial.t_h >= end - NOISE_WINDOW_S) & (trial.t_h < end)
    f, t = trial.force[sel], trial.t_h[sel]
    if f.size < 20:
        return None
    k = np.floor((t - t[0]) / BIN_S).astype(np.int64)
    means = np.bincount(k, f) / np.maximum(np.bincount(k), 1)
    means = means[np.bincount(k) > 0]
    noise = float(np.std(means)) if means.size >= 5 else 0.0
    # (a load cell that reads one value through the fall does not tell its noise)
    return noise if noise > 0.0 else None


class ForceView:
    """A :class:`~transparency_ros.analysis.discrepancy.drop.DropProblem` judged on the ride's
    load-cell residual (module docstring); all else is the problem's. Its effects' parameters
    are fitted alone (those found before held: their values come from the kinematics), pairs
    are not tried, and an effect that makes the kinematic held-out error worse by more than
    ``KINEMATICS_KEPT`` is not meaningful here."""

    channel = "load cell in the ride"
    unit = "times its uncertainty"
    # its bins pool the trials: no refit per trial (DropCogging.spread), not the problem's
    trial_index = None
    pairs = False
    joint_refit = False
    declared_stage = False

    def __init__(self, problem: Any) -> None:
        self.base = problem
        self.fit = _Bins(problem.fit_trials, problem.fit.sim)
        self.held = _Bins(problem.held_trials, problem.held.sim)
        self._kinematic: float | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.base, name)

    def usable(self) -> bool:
        return self.fit.size >= 10 and self.held.size >= 10

    def start(self, effects: Sequence[DropEffect], params: Sequence[FloatArray]) -> None:
        """The bins compared (``_Bins.settle``: the ride after the last flight the recording
        or the effects found so far show) and the kinematic held-out RMSE those effects leave
        (``accepts``' bound)."""
        for s in (self.fit, self.held):
            s.settle(self.base.physics(effects, params, s.trials))
        err = self.base.error(effects, params, True)
        self._kinematic = float(np.sqrt(np.mean(err**2)))

    def error(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray], held: bool
    ) -> FloatArray:
        return self.error_sets(effects, [params], held)[0]

    def error_sets(
        self,
        effects: Sequence[DropEffect],
        param_sets: Sequence[Sequence[FloatArray]],
        held: bool,
    ) -> list[FloatArray]:
        s = self.held if held else self.fit
        return s.error_many([self.base.physics(effects, p, s.trials) for p in param_sets])

    def noise_floor(self) -> float:
        return 1.0

    def structure_left(self, err: FloatArray) -> bool:
        return bool(err.size) and float(np.sqrt(np.mean(err**2))) > FORCE_SIGNIFICANT

    def leftover_scope(self, err: FloatArray) -> None:
        return None

    def sensor_scope(
        self,
        effects: Sequence[DropEffect],
        after_search: bool = False,
        modelled: Sequence[DropEffect] = (),
    ) -> None:
        return None

    def accepts(self, effects: Sequence[DropEffect], params: Sequence[FloatArray]) -> bool:
        """Not at the cost of the kinematics (``KINEMATICS_KEPT``), nor against the falls
        (DropProblem.accepts: rail friction the falls say is not there)."""
        if not self.base.accepts(effects, params):
            return False
        if self._kinematic is None:
            return True
        err = self.base.error(effects, params, True)
        return float(np.sqrt(np.mean(err**2))) <= KINEMATICS_KEPT * self._kinematic

    def shows(
        self,
        effects: Sequence[DropEffect],
        params: Sequence[FloatArray],
        added: Sequence[DropEffect],
        new_params: Sequence[FloatArray],
    ) -> str:
        """What the load cell shows of ``added`` (``new_params``: of every effect) acting, where
        it does ("" where not): the held-out residual of the model (``effects``, ``params``)
        is structure (``FORCE_SIGNIFICANT``), and with ``added`` it is not. It reads the
        shuttle's weight directly: on zoo_10297 (a 0.7 ms sensor delay) the weight took the
        ride's residual from 34 to 0.7 uncertainties while the encoder's held-out error rose
        by 8 %, and a soft contact was named for the delay."""
        before = self.error(effects, params, True)
        after = self.error([*effects, *added], new_params, True)
        rms = [float(np.sqrt(np.mean(e**2))) if e.size else 0.0 for e in (before, after)]
        if rms[0] > FORCE_SIGNIFICANT >= rms[1]:
            return f"shown by the {self.channel}: {rms[0]:.3g} -> {rms[1]:.3g} {self.unit}"
        return ""

    def phases(self) -> dict[str, npt.NDArray[np.bool_]]:
        from transparency_ros.analysis.discrepancy.drop import _phase_masks  # noqa: PLC0415

        times = self.held.kept_times()
        parts = [_phase_masks(t, s) for t, s in zip(self.held.trials, times, strict=True)]
        names = parts[0].keys() if parts else ()
        return {name: np.concatenate([p[name] for p in parts]) for name in names}

    def segments(self) -> tuple[npt.NDArray[np.int64], list[tuple[str, float, float]]]:
        index, labels = [], []
        kept = self.held.kept_times()
        for k, (t, times) in enumerate(zip(self.held.trials, kept, strict=True)):
            begin = float(times[0]) if times.size else t.contact_s + FORCE_LEAD_S
            labels.append((t.name, begin, t.end_s))
            index.append(np.full(times.size, k, dtype=np.int64))
        return np.concatenate(index), labels


def force_view(problem: Any) -> ForceView | None:
    """The problem's load-cell view, or None where too few bins can be compared."""
    view = ForceView(problem)
    return view if view.usable() else None


__all__ = ["FORCE_SIGNIFICANT", "ForceView", "force_view"]
