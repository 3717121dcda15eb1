"""Drop tests (Sec. 3.1) for the discrepancy tool: the paper's contact model as the nominal model.

Nominal model (eq. 2, Table 1): the shuttle falls freely from its release; at contact an
instantaneous, perfectly inelastic collision joins it to the arm, and from then on one body of
inertia J_r + J_arm + m_s r^2 turns under the impedance k_s (theta_d - theta), viscous drag b_v
and Coulomb friction tau_coul (stick-slip, breakaway at tau_coul). The shuttle is weightless on
the arm, the rail has no friction, the gearbox no backlash, the arm is rigid and the encoder
exact: everything eq. (2) leaves out is a candidate effect, and each one changes exactly the
piece of this simulator where its physics acts:

* ``payload_gravity``: the shuttle's weight m_s g r cos(theta) loads the arm while they touch;
* ``restitution``: impacts are elastic with coefficient e; the shuttle flies off, falls back
  and strikes again, until the bounces die out (approach slower than 5 cm/s: it stays);
* ``impact_speed_loss``: rail friction brakes the shuttle (it arrives slower than free fall);
* ``structural_compliance``: the contact is a stiff spring, not an instant collision;
* ``backlash``: a dead band between the motor (encoder) and the arm;
* ``stiction``, ``torque_offset``, ``parameter_drift`` (J_r, b_v, tau_coul), ``sensor_delay``
  and ``quantization`` (of the encoder), as for the torque-driven model.

Each trial is compared in two pieces (multiple shooting, so an error in one does not swamp the
other): the fall, from the release to 3 ms before contact (the shuttle height; the release time
is the vertex of a parabola fitted to the fall), and the impact, from the recorded state 3 ms before
contact to 0.25 s after (encoder position and shuttle height). Heights are compared as the arm
angle they correspond to (height / r), so every error is in rad. All trials of a problem are
integrated together, and every candidate value of a fit with them, by the compiled
integrator of :mod:`transparency_ros.analysis.discrepancy.drop_kernel`.

This file is the problem the loop works on (:class:`DropProblem`: compared samples, phases,
noise floor). A trial as read from its bag is in ``drop_trials``, the physics, nominal values
and simulator in ``drop_physics``, the candidate effects in ``drop_effects``.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from functools import cached_property

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.drop_alike import told_apart
from transparency_ros.analysis.discrepancy.drop_bounce import shuttle_bounces
from transparency_ros.analysis.discrepancy.drop_clip import drive_clip
from transparency_ros.analysis.discrepancy.drop_effects import (
    LOCAL_GRAVITY_SPREAD,
    DropEffect,
    DropQuantization,
)
from transparency_ros.analysis.discrepancy.drop_force import ForceView, force_view
from transparency_ros.analysis.discrepancy.drop_library import drop_library
from transparency_ros.analysis.discrepancy.drop_physics import (
    DropNominal,
    DropPhysics,
    DropSimulator,
    load_drop_nominal,
    stack_physics,
)
from transparency_ros.analysis.discrepancy.drop_trials import (
    LEAD_S,
    MODEL_STRIKE_SIGN,
    DropTrial,
    load_drop_trial,
    rest_position,
)
from transparency_ros.analysis.discrepancy.fitting import CRITERION, aic
from transparency_ros.analysis.discrepancy.model import GRAVITY, FloatArray
from transparency_ros.analysis.discrepancy.problem import (
    SIGNIFICANT,
    Trace,
    position_noise,
    spectrum_peak,
)
from transparency_ros.analysis.discrepancy.steps import Base, Step
from transparency_ros.core.errors import ConfigError

__all__ = ["PHASES", "DropProblem", "DropTrial", "load_drop_nominal", "load_drop_trial"]

BoolArray = npt.NDArray[np.bool_]
MODEL_ERROR_SHARE = 0.2
PHASES = ("before_contact", "impact", "deflection", "rebound", "reversal", "stuck")


class _Set:
    """The compared samples of some trials: fall heights and impact-piece samples."""

    def __init__(self, trials: Sequence[DropTrial]) -> None:
        self.trials = list(trials)
        self.sim = DropSimulator(trials)
        self.fall: list[tuple[FloatArray, FloatArray]] = []  # (t since release, height)
        # the fall's error is linear in its acceleration a: c + a k [rad at the arm's length],
        # both fixed per trial and made once here. A recording without its release has the
        # fall's start (height, time) fitted for each acceleration (a projection P onto
        # [1, t]): only the fall's curvature is compared, c = (P h - h) / r,
        # k = (P t^2/2 - t^2/2) / r; with the release, c = (h_held - h) / r, k = -t^2/2 / r
        self.fall_terms: list[tuple[FloatArray, FloatArray]] = []
        self.q: list[tuple[FloatArray, FloatArray]] = []  # (t since piece start, q)
        self.h: list[tuple[FloatArray, FloatArray]] = []  # (t since piece start, height)
        for t in trials:
            fall = (t.t_h > t.release_s) & (t.t_h < t.start_s)
            t_f, h_f = t.t_h[fall][::10] - t.release_s, t.height[fall][::10]
            self.fall.append((t_f, h_f))
            half = 0.5 * t_f**2
            if t.release_recorded:
                self.fall_terms.append(((t.held_height_m - h_f) / t.arm_m, -half / t.arm_m))
            else:
                basis = np.stack([np.ones_like(t_f), t_f], axis=1)
                projection = basis @ np.linalg.pinv(basis)
                self.fall_terms.append(
                    ((projection @ h_f - h_f) / t.arm_m, (projection @ half - half) / t.arm_m)
                )
            sel = (t.t_q >= t.start_s) & (t.t_q <= t.end_s)
            self.q.append((t.t_q[sel] - t.start_s, t.q[sel]))
            sel = (t.t_h >= t.start_s) & (t.t_h <= t.end_s)
            self.h.append((t.t_h[sel][::10] - t.start_s, t.height[sel][::10]))
        # d fall error / d gamma (local gravity g (1 + gamma), see _falls), all trials
        slope = np.concatenate([GRAVITY * k for _, k in self.fall_terms]) if trials else None
        self._gravity_slope = slope
        self._gravity_norm = float(slope @ slope) if slope is not None else 0.0

    def error(self, ph: DropPhysics) -> FloatArray:
        return self.error_many([ph])[0]

    def error_many(self, physics: Sequence[DropPhysics]) -> list[FloatArray]:
        """The error of each physics, all simulated in one run."""
        n = len(self.trials)
        ph = stack_physics(physics, n)
        t_sim, q_sim, y_sim = self.sim.run(ph, len(physics))
        rail_n, delay_s = np.asarray(ph.rail_friction_n), np.asarray(ph.delay_s)
        step_rad = np.asarray(ph.encoder_step_rad)
        out = []
        for j in range(len(physics)):
            falls = self._falls(rail_n[j * n : (j + 1) * n])
            parts = []
            for i, trial in enumerate(self.trials):
                row, r = j * n + i, trial.arm_m
                parts.append(falls[i])
                t_q, q = self.q[i]
                q_model = np.interp(t_q - delay_s[row], t_sim, q_sim[row])
                step = step_rad[row]
                miss = q_model - q
                if step > 0:
                    # a reading of k counts says the arm was within half a count of k steps:
                    # the model errs only by how far it is outside that interval
                    miss = np.sign(miss) * np.maximum(np.abs(miss) - step / 2, 0.0)
                parts.append(miss)
                t_h, h = self.h[i]
                parts.append((np.interp(t_h, t_sim, y_sim[row]) - h) / r)
            out.append(np.concatenate(parts))
        return out

    def _falls(self, rail_n: FloatArray) -> list[FloatArray]:
        """The fall's error of every trial [rad at the arm's length]: free fall from the hold
        (or, without the release recorded, its curvature only), braked by the rail. Local
        gravity is not the tool's g: it differs by up to ``LOCAL_GRAVITY_SPREAD`` over the
        Earth, so without rail friction the fall's acceleration is g (1 + gamma), gamma
        fitted within that spread for all trials together (on the independent rig, a 0.03 %
        mismatch left 0.8 mrad in a fall and hid a coarse encoder). With rail friction the
        acceleration is what it measures, and g is the tool's."""
        residual = [
            c + (GRAVITY - float(rail_n[i]) / trial.mass_kg) * k
            for i, (trial, (c, k)) in enumerate(zip(self.trials, self.fall_terms, strict=True))
        ]
        if np.any(rail_n != 0.0) or self._gravity_slope is None or self._gravity_norm <= 0.0:
            return residual
        slope = self._gravity_slope
        gamma = -float(np.concatenate(residual) @ slope) / self._gravity_norm
        gamma = float(np.clip(gamma, -LOCAL_GRAVITY_SPREAD, LOCAL_GRAVITY_SPREAD))
        terms = self.fall_terms
        return [r + gamma * GRAVITY * k for r, (_, k) in zip(residual, terms, strict=True)]

    def layout(self) -> list[tuple[int, str, FloatArray]]:
        """(trial, piece, absolute times) in the order :meth:`error` concatenates them."""
        out = []
        for i, trial in enumerate(self.trials):
            out.append((i, "fall", self.fall[i][0] + trial.release_s))
            out.append((i, "encoder", self.q[i][0] + trial.start_s))
            out.append((i, "height", self.h[i][0] + trial.start_s))
        return out


class DropProblem:
    """Drop-test trials of one actuator against eq. (2)."""

    scoped_sensor = "encoder"  # the sensor leftover_scope judges alone (findings.leftover)

    def __init__(
        self,
        trials: Sequence[DropTrial],
        nominal: DropNominal,
        candidates: Sequence[DropEffect] | None = None,
    ) -> None:
        actuators = {t.actuator for t in trials}
        if len(actuators) != 1:
            raise ConfigError(f"one actuator per analysis, got {sorted(actuators)}")
        if len(trials) < 2:
            raise ConfigError("a drop-test analysis needs at least 2 trials (fit and held out)")
        self.actuator = next(iter(actuators))
        # held-out trials spread over the heights: split in the order of drop height
        ordered = sorted(trials, key=lambda t: (t.held_height_m, t.name))
        # every third trial held out (at least one)
        held = [t for i, t in enumerate(ordered) if i % 3 == 2] or ordered[-1:]
        self.fit_trials = [t for t in ordered if all(t is not h for h in held)]
        self.held_trials = held
        self.fit = _Set(self.fit_trials)
        self.held = _Set(self.held_trials)
        self.model = nominal
        # concealed drop-test effects remove >= 80 % of the held-out error above the floor in the
        # survey's campaigns; restitution or an offset standing in for friction that varies with
        # position (outside the library) 50-65 %
        self.min_improvement = 0.75
        # the model's own error in a fitted value, a share of it (findings.widen): on the zoo's
        # development campaigns (seeds 0-89, never reported) the intervals from the fit alone
        # covered 17 of 62 true values; with a fifth of the value added, 55 of 62 (the rest:
        # backlash widths fitted at twice the truth, see docs/discrepancy.md)
        self.model_error_share = MODEL_ERROR_SHARE
        mass = float(np.mean([t.mass_kg for t in trials]))
        self._candidates = (
            list(candidates)
            if candidates is not None
            else drop_library(
                mass,
                nominal.coulomb_nm[self.actuator],
                float(np.mean([t.loaded_inertia_kgm2 for t in trials])),
                float(np.median(np.concatenate([np.diff(t.t_q) for t in trials]))),
                noise_floor_rad=self.noise_floor(),
                encoder_count_rad=self.encoder_count,
                torques_recorded=all(t.effort is not None for t in trials),
                clip=drive_clip(trials),
                bounces=shuttle_bounces(trials),
            )
        )
        self.nominal = {
            k: v for k, v in nominal.as_dict().items() if k.startswith(f"{self.actuator}.")
        }
        self.split = {
            "fit": [t.name for t in self.fit_trials],
            "heldout": [t.name for t in self.held_trials],
        }
        self.notes = conventions(trials)
        # what the recordings predict: the torque that held the arm off theta_d before contact
        # (see expected; in the rig's theta sense) and the shuttle's weight on the arm
        self._held_nm = -float(
            np.median([t.sense * t.k_s * (t.theta_d - rest_position(t)) for t in trials])
        )
        self.declared_weight_nm = float(np.mean([t.mass_kg * GRAVITY * t.arm_m for t in trials]))

    def physics(
        self,
        effects: Sequence[DropEffect],
        params: Sequence[FloatArray],
        trials: Sequence[DropTrial],
    ) -> DropPhysics:
        a = self.actuator
        ones = np.ones(len(trials))
        ph = DropPhysics(
            rotor_inertia_kgm2=ones * self.model.reflected_inertia_kgm2[a],
            viscous_nms_per_rad=ones * self.model.viscous_nms_per_rad[a],
            coulomb_nm=ones * self.model.coulomb_nm[a],
            static_nm=ones * self.model.coulomb_nm[a],
            sense=np.array([t.sense for t in trials]),
        )
        for effect, p in zip(effects, params, strict=True):
            ph = effect.apply(ph, p, self)
        return ph

    def accepts(self, effects: Sequence[DropEffect], params: Sequence[FloatArray]) -> bool:
        """Whether the held-out falls allow the model's rail friction: the shuttle falls alone
        on its rail, so the fall's curvature measures the braking directly. A braking force
        the falls' criterion (:func:`aic`, their error with it against free fall under local
        gravity) says is not there by ``CRITERION`` is refused, whatever it explains in the
        impact: zoo_13822 (a torque offset and a backlash hidden) named rail friction of
        0.38 N with the backlash, which took the held-out falls from 0.74 to 1.01 mrad."""
        rail = np.broadcast_to(
            np.asarray(self.physics(effects, params, self.held_trials).rail_friction_n, float),
            (len(self.held_trials),),
        )
        if not np.any(rail != 0.0):
            return True
        free = self._free_falls_aic
        braked = np.concatenate(self.held._falls(rail))
        return free is None or aic(braked, 1) - free <= CRITERION

    @cached_property
    def _free_falls_aic(self) -> float | None:
        """The held-out falls' criterion in free fall (``accepts``), or None without falls."""
        free = np.concatenate(self.held._falls(np.zeros(len(self.held_trials))))
        return aic(free, 1) if free.size else None

    def expected(self, effect: DropEffect, p: FloatArray) -> bool:
        """Whether the recording itself predicts this fitted effect, within 30 %: a constant
        torque offset, when the arm was held away from theta_d before contact by as much
        (k_s (theta_d - rest) = -offset: a torque the weight, which acts only in contact,
        cannot explain). (The weight's size is declared, not fitted: ``DeclaredWeight``.)"""
        if effect.name == "torque_offset":
            return abs(float(p[0]) - self._held_nm) <= 0.3 * abs(float(p[0]))
        return False

    def candidates(self) -> list[DropEffect]:
        return list(self._candidates)

    def initial(self, effect: DropEffect) -> FloatArray:
        return effect.initial(self)

    def error(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray], held: bool
    ) -> FloatArray:
        s = self.held if held else self.fit
        return s.error(self.physics(effects, params, s.trials))

    def error_sets(
        self,
        effects: Sequence[DropEffect],
        param_sets: Sequence[Sequence[FloatArray]],
        held: bool,
    ) -> list[FloatArray]:
        s = self.held if held else self.fit
        return s.error_many([self.physics(effects, params, s.trials) for params in param_sets])

    def phases(self) -> dict[str, BoolArray]:
        return dict(self._phases)

    @cached_property
    def _phases(self) -> dict[str, BoolArray]:
        """The held-out elements' motion phases (made once: the report asks several times)."""
        masks: dict[str, list[BoolArray]] = {name: [] for name in PHASES}
        for i, _piece, t in self.held.layout():
            trial = self.held.trials[i]
            for name, mask in _phase_masks(trial, t).items():
                masks[name].append(mask)
        return {name: np.concatenate(parts) for name, parts in masks.items()}

    def segments(self) -> tuple[npt.NDArray[np.int64], list[tuple[str, float, float]]]:
        index, labels = [], []
        for i, piece, t in self.held.layout():
            trial = self.held.trials[i]
            if piece != "height":  # the impact piece's encoder and height share a segment
                labels.append(
                    (
                        trial.name,
                        *(
                            (trial.release_s, trial.start_s)
                            if piece == "fall"
                            else (trial.start_s, trial.end_s)
                        ),
                    )
                )
            index.append(np.full(t.size, len(labels) - 1, dtype=np.int64))
        return np.concatenate(index), labels

    def force_view(self) -> ForceView | None:
        """The trials seen through the load cell while the shuttle rides (drop_force): one
        view, made once, for the loop's last stage and ``shows_elsewhere``."""
        return self._load_cell

    def shows_elsewhere(self, step: Step, base: Base) -> bool:
        """Whether the load cell in the ride shows what ``step`` adds to the model ``base`` is
        the error of (ForceView.shows; False without a usable load cell); what it shows goes
        into the step's evidence (``elsewhere``)."""
        view = self._load_cell
        if view is not None:
            step.elsewhere = view.shows(base.effects, base.params, step.added, step.params)
        return bool(step.elsewhere)

    def told_apart(self, named: Sequence[DropEffect], other: Sequence[DropEffect]) -> str:
        """What would tell ``named`` from ``other`` (drop_alike.told_apart)."""
        return told_apart(self, named, other)

    @cached_property
    def _load_cell(self) -> ForceView | None:
        return force_view(self)

    def noise_floor(self) -> float:
        """RMS error sensor noise alone gives: encoder (quantization) and potentiometer noise,
        weighted by how many samples of each are compared."""
        q_noise, h_noise = self._sensor_noise
        n_q = sum(q.size for _, q in self.fit.q)
        n_h = sum(h.size for _, h in self.fit.h) + sum(h.size for _, h in self.fit.fall)
        return float(math.sqrt((n_q * q_noise**2 + n_h * h_noise**2) / max(1, n_q + n_h)))

    @property
    def encoder_noise_rad(self) -> float:
        """The encoder's noise at rest [rad] (its readings before contact)."""
        return self._sensor_noise[0]

    @cached_property
    def _sensor_noise(self) -> tuple[float, float]:
        """The encoder's and the height sensor's noise [rad at the arm's length] at rest
        (made once: the loop asks for them at every candidate step of a sensor effect)."""
        q_noise = float(
            np.sqrt(
                np.mean(
                    [position_noise(t.q[t.t_q < t.start_s][-50:]) ** 2 for t in self.fit_trials]
                )
            )
        )
        h_noise = float(
            np.sqrt(
                np.mean(
                    [
                        (position_noise(t.height[t.t_h < t.t_h[0] + 0.02]) / t.arm_m) ** 2
                        for t in self.fit_trials
                    ]
                )
            )
        )
        return q_noise, h_noise

    def structure_left(self, err: FloatArray) -> bool:
        """Whether the held-out error ``err`` still has something to explain: the pooled error
        above 1.5x the noise floor, or the encoder's part above 1.5x the encoder's own floor
        (see leftover_scope). Pooled, a potentiometer's noise (up to 2 mrad at the arm) hid an
        encoder's error of several of its counts (a torque offset of 0.07 N m on the zoo)."""
        pooled = float(np.sqrt(np.mean(err**2))) > SIGNIFICANT * self.noise_floor()
        return pooled or self.leftover_scope(err) is not None

    def leftover_scope(self, err: FloatArray) -> tuple[BoolArray, float] | None:
        """The encoder's error elements and floor, when its part of ``err`` is above 1.5x that
        floor: what is left there is judged there (a dynamics effect that removes it removes
        the encoder's error; one fitted to the heights' noise does not). The encoder's floor is
        its noise at rest or a count's quantization error (count / sqrt 12), whichever is
        larger: a fine encoder at rest reads one value, a floor of 0 that any error exceeds."""
        enc = self._encoder_elements
        if not enc.any():
            return None
        floor = self._encoder_floor
        return (
            (enc, floor) if float(np.sqrt(np.mean(err[enc] ** 2))) > SIGNIFICANT * floor else None
        )

    @cached_property
    def _encoder_floor(self) -> float:
        return max(self._sensor_noise[0], self.encoder_count / math.sqrt(12))

    @cached_property
    def position_span(self) -> float:
        """The range of positions the fitting trials' compared readings visited [rad]."""
        q = np.concatenate([q for _, q in self.fit.q])
        return float(np.ptp(q)) if q.size else 0.0

    @cached_property
    def encoder_count(self) -> float:
        """One count of the encoder [rad]: the finest spacing of the values a trial read, or of
        its steps (a moving arm's successive samples are many counts apart, but steps differ
        by whole counts); the median over the fitting trials (0: none seen)."""
        counts = []
        for t in self.fit_trials:
            steps = np.abs(np.diff(t.q))
            spacing = np.r_[np.diff(np.unique(t.q)), np.diff(np.unique(steps[steps > 1e-12]))]
            spacing = spacing[spacing > 1e-9]
            counts.append(float(np.min(spacing)) if spacing.size else 0.0)
        return float(np.median(counts)) if counts else 0.0

    def sensor_scope(
        self,
        effects: Sequence[DropEffect],
        after_search: bool = False,
        modelled: Sequence[DropEffect] = (),
    ) -> tuple[BoolArray, float] | None:
        """For effects that all act on the encoder's readings alone (its lattice, its lateness):
        the held-out error elements of the encoder and its own floor (see leftover_scope), on
        which they are judged. Such an effect cannot touch the heights' or the fall's residual;
        judged on all of it, a coarse encoder went unnamed beside 0.3 mrad the heights kept for
        another reason (a friction hump the encoder's 3 mrad lattice hides). After the search
        (``after_search``) the lattice is judged against the encoder's noise at rest, not
        against the count / sqrt 12 it would explain (Discoverer._checked_last); so is every
        such effect once the lattice is in the model (``modelled``: the effects found), which
        then makes the readings' steps itself (zoo_12260: after a 1024-count lattice the
        encoder's error was 1.67 mrad, under count / sqrt 12 = 1.77, and a 1.3 ms delay took
        it to 0.38: the model reads more finely than that floor says)."""
        if not effects or any(e.sensor != "encoder" for e in effects):
            return None
        lattice = any(isinstance(e, DropQuantization) for e in modelled)
        if lattice or (after_search and all(e.checked_last for e in effects)):
            return self._encoder_elements, self._sensor_noise[0]
        return self._encoder_elements, self._encoder_floor

    def trial_index(self, held: bool) -> npt.NDArray[np.int64]:
        """The trial (of the fitting or held-out set) each element of :meth:`error` is of."""
        s = self.held if held else self.fit
        return np.concatenate([np.full(t.size, i) for i, _, t in s.layout()]).astype(np.int64)

    @cached_property
    def _encoder_elements(self) -> BoolArray:
        return np.concatenate(
            [np.full(t.size, piece == "encoder") for _, piece, t in self.held.layout()]
        )

    def residual_peak_hz(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray]
    ) -> float:
        """Where the held-out encoder residual after contact has most power (uniformly
        resampled at 1 kHz)."""
        ph = self.physics(effects, params, self.held_trials)
        t_sim, q_sim, _ = self.held.sim.run(ph)
        best_f, best_p = math.nan, -1.0
        for i in range(len(self.held_trials)):
            t_q, q = self.held.q[i]
            grid = np.arange(LEAD_S, t_q[-1], 1e-3)
            res = np.interp(grid, t_q, q) - np.interp(grid - ph.delay_s, t_sim, q_sim[i])
            f, power = spectrum_peak(res, 1000.0, above_hz=2.0)
            if power > best_p:
                best_f, best_p = f, power
        return best_f

    def trace(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray], segment: int
    ) -> Trace:
        _, labels = self.segments()
        name = labels[segment][0]
        i = next(k for k, t in enumerate(self.held_trials) if t.name == name)
        trial = self.held_trials[i]
        t_sim, q_nom, _ = self.held.sim.run(self.physics([], [], self.held_trials))
        ph = self.physics(effects, params, self.held_trials)
        _, q_fin, _ = self.held.sim.run(ph)
        t_q, q = self.held.q[i]
        return Trace(
            f"{trial.name} (drop {trial.held_height_m:.2f} m), time from 3 ms before contact",
            t_q,
            q,
            np.interp(t_q, t_sim, q_nom[i]),
            np.interp(t_q - ph.delay_s, t_sim, q_fin[i]),
            "encoder position [rad]",
        )


def conventions(trials: Sequence[DropTrial]) -> list[str]:
    """What the analysis assumed or detected about the rig, in words a user can act on: the
    strike's direction over all trials, then each trial's own notes."""
    turn = {1: "positive", -1: "negative"}
    signs = Counter(t.strike_sign for t in trials)
    parts = [f"{turn[k]} theta in {n} of {len(trials)} trials" for k, n in sorted(signs.items())]
    convention = "the model's convention" if set(signs) == {MODEL_STRIKE_SIGN} else "see below"
    notes = [f"strike direction: {', '.join(parts)} ({convention})"]
    for trial in trials:
        notes += [f"{trial.name}: {note}" for note in trial.notes]
    return notes


def _phase_masks(trial: DropTrial, t: FloatArray) -> dict[str, BoolArray]:
    """Phase of each time ``t`` of a trial, from its recorded data: before contact; the first
    impact (load cell above threshold); then by the arm's recorded motion: away from rest
    (deflection), back towards it (rebound), within 3 ms of a turn (reversal), or stuck."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    rest = rest_position(trial)
    dt = float(np.median(np.diff(trial.t_q)))
    n = max(5, round(0.01 / dt) | 1)
    speed = (
        savgol_filter(trial.q, n, 2, deriv=1, delta=dt)
        if trial.q.size > n
        else np.gradient(trial.q, trial.t_q)
    )
    w = np.interp(t, trial.t_q, speed)
    q = np.interp(t, trial.t_q, trial.q)
    before = t < trial.contact_s
    impact = ~before & (t < trial.contact_end_s)
    after = ~before & ~impact
    turns = trial.t_q[1:][np.sign(speed[1:]) != np.sign(speed[:-1])]
    near_turn = np.zeros(t.size, dtype=bool)
    if turns.size:
        j = np.clip(np.searchsorted(turns, t), 1, turns.size) - 1
        near = np.minimum(
            np.abs(t - turns[j]), np.abs(t - turns[np.minimum(j + 1, turns.size - 1)])
        )
        near_turn = near < 0.003
    stuck = after & (np.abs(w) < 0.02)
    moving = after & ~stuck
    away = np.sign(w) == np.sign(q - rest)
    return {
        "before_contact": before,
        "impact": impact,
        "deflection": moving & ~near_turn & away,
        "rebound": moving & ~near_turn & ~away,
        "reversal": moving & near_turn,
        "stuck": stuck,
    }
