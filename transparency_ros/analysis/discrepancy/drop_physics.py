"""The drop test's physics as the discrepancy tool simulates it: :class:`DropPhysics` (eq. (2)'s
values and every candidate's), the nominal values per actuator (:class:`DropNominal`, Table 1 or
a YAML spec) and :class:`DropSimulator`, which integrates the impact pieces of all trials, and
every candidate value tried with them, in one call of the compiled kernel
(:mod:`transparency_ros.analysis.discrepancy.drop_kernel`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from transparency_ros.analysis.discrepancy.drop_kernel import impact
from transparency_ros.analysis.discrepancy.drop_trials import (
    DropTrial,
    rest_position,
    shuttle_state,
)
from transparency_ros.analysis.discrepancy.model import FloatArray, read_spec
from transparency_ros.core.config import finite_number, get_actuator
from transparency_ros.core.contact_model import restitution_damping_ratio
from transparency_ros.core.errors import ConfigError

# the simulated trajectories are sampled every STEP_S and integrated in SUBSTEPS per sample
# (collisions and reversals are located within a step; 25 us gives the same held-out error as
# 10 us to within half the noise floor of these rigs)
STEP_S = 1e-4
SUBSTEPS = 4
SPRING_SUBSTEPS = 10  # the contact's onset and end fall within a step
OMEGA_STEP = 0.025  # radians of the contact spring's oscillation per step
TORSION_STEP = 0.15  # radians of a torsional spring's oscillation per step
TORSION_STABLE = 0.5  # radians of its fastest oscillation (the arm without the shuttle)


@dataclass(frozen=True)
class DropPhysics:
    """What the simulator integrates; the nominal values are eq. (2)'s. Every value is a scalar
    or an array over the simulated rows (trials, times the candidate values tried at once)."""

    rotor_inertia_kgm2: FloatArray  # J_r
    viscous_nms_per_rad: FloatArray  # b_v
    coulomb_nm: FloatArray  # tau_coul
    static_nm: FloatArray  # breakaway torque (nominal: tau_coul)
    torque_offset_nm: FloatArray | float = 0.0
    weight_torque_nm: FloatArray | float = 0.0  # m_s g r on the arm while touching
    restitution: FloatArray | float = 0.0
    stiffness_n_per_m: FloatArray | float = math.inf  # contact spring (inf: instant collision)
    rail_friction_n: FloatArray | float = 0.0
    backlash_rad: FloatArray | float = 0.0
    # where the arm starts in the dead band: arm - motor in half bands, +1 on the far flank
    # from the strike (the whole band to close), -1 on the flank the strike loads
    backlash_start: FloatArray | float = 0.0
    delay_s: FloatArray | float = 0.0
    encoder_step_rad: FloatArray | float = 0.0
    torque_limit_nm: FloatArray | float = math.inf  # the drive's impedance torque clipped
    # the motor's cogging, A sin(N q + phase) in the model's sense of q
    cogging_nm: FloatArray | float = 0.0
    cogging_periods: FloatArray | float = 0.0
    cogging_phase_rad: FloatArray | float = 0.0
    # a torsional spring between motor and arm (0: rigid) and the damping ratio of their mode
    # with the shuttle on the arm
    torsion_nm_per_rad: FloatArray | float = 0.0
    torsion_damping_ratio: FloatArray | float = 0.0
    # +1 where the trial is analysed as recorded, -1 where mirrored (the rig turns positive):
    # what turns a torque in the rig's theta sense into the model's (not integrated)
    sense: FloatArray | float = 1.0

    def rows(self, n: int) -> DropPhysics:
        """Every value as an array of ``n`` rows."""
        return DropPhysics(
            **{
                f.name: np.broadcast_to(np.asarray(getattr(self, f.name), float), (n,))
                for f in fields(self)
            }
        )


def stack_physics(physics: Sequence[DropPhysics], n: int) -> DropPhysics:
    """Several physics of ``n`` trials each as one of ``len(physics) * n`` rows."""
    rows = [ph.rows(n) for ph in physics]
    return DropPhysics(
        **{f.name: np.concatenate([getattr(r, f.name) for r in rows]) for f in fields(DropPhysics)}
    )


@dataclass(frozen=True)
class DropNominal:
    """Nominal values per actuator (Table 1), overridable from a YAML spec."""

    reflected_inertia_kgm2: dict[str, float]
    viscous_nms_per_rad: dict[str, float]
    coulomb_nm: dict[str, float]

    def as_dict(self) -> dict[str, float]:
        out = {}
        for f in fields(self):
            for actuator, value in getattr(self, f.name).items():
                out[f"{actuator}.{f.name}"] = value
        return out


def load_drop_nominal(path: str | Path | None, trials: Sequence[DropTrial]) -> DropNominal:
    """Eq. (2) with Table 1's J_r, b_v, tau_coul for each actuator of the trials; a YAML spec
    may override any of ``reflected_inertia_kgm2``, ``viscous_nms_per_rad``, ``coulomb_nm``."""
    actuators = sorted({t.actuator for t in trials})
    values: dict[str, dict[str, float]] = {f.name: {} for f in fields(DropNominal)}
    for name in actuators:
        try:
            a = get_actuator(name)
        except (ConfigError, KeyError) as err:
            raise ConfigError(f"actuator {name!r} of the bags is not in Table 1: {err}") from err
        values["reflected_inertia_kgm2"][name] = a.reflected_inertia_kgm2
        values["viscous_nms_per_rad"][name] = a.viscous_damping_nms_per_rad
        values["coulomb_nm"][name] = a.coulomb_friction_nm
    if path is not None:
        p = Path(path)
        data = read_spec(p)
        unknown = sorted(set(data) - set(values))
        if unknown:
            raise ConfigError(f"{p}: unknown drop-test terms {unknown}; known: {list(values)}")
        for key, value in data.items():
            for name in actuators:
                values[key][name] = finite_number(value, f"{p}: {key}")
    return DropNominal(**values)


class DropSimulator:
    """The impact pieces of a set of trials, integrated together."""

    def __init__(self, trials: Sequence[DropTrial]) -> None:
        if not trials:
            raise ValueError("DropSimulator: no trials to simulate")
        self.trials = list(trials)
        self.mass = np.array([t.mass_kg for t in trials])
        self.arm = np.array([t.arm_m for t in trials])
        self.arm_inertia = np.array([t.arm_inertia_kgm2 for t in trials])
        self.loaded_inertia = np.array([t.loaded_inertia_kgm2 for t in trials])
        self.k_s = np.array([t.k_s for t in trials])
        self.theta_d = np.array([t.theta_d for t in trials])
        self.q0 = np.array([rest_position(t) for t in trials])
        # recorded heights are above the tip at rest, r sin(q0): the simulator's are above the
        # axis (an arm resting away from horizontal puts its tip r sin(q0) higher)
        self.tip0 = self.arm * np.sin(self.q0)
        y0, v0 = zip(*(shuttle_state(t) for t in trials), strict=True)
        self.y0, self.v0 = np.array(y0) + self.tip0, np.array(v0)
        lengths = np.array([t.end_s - t.start_s for t in trials]) + 0.03
        self.duration = float(lengths.max())
        # each trial's own output steps (a shorter trial is not integrated to the longest's end)
        self.own_steps = np.ceil(lengths / STEP_S) + 1

    def run(
        self, ph: DropPhysics, tiles: int = 1, shortcuts: bool = True
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(time from each trial's start, motor position, shuttle height above the tip at
        rest), (rows, steps): the
        trials ``tiles`` times over, row ``j * n_trials + i`` with physics row alike. With
        ``shortcuts`` (the same values to the bit where a trial is compared, see
        :func:`impact`) a trial's row past its own end holds its last value."""
        n = len(self.trials) * tiles
        ph = ph.rows(n)
        steps = math.ceil(self.duration / STEP_S) + 1
        m = np.tile(self.mass, tiles)
        stiffness = np.asarray(ph.stiffness_n_per_m, dtype=float)
        zeta = restitution_damping_ratio(np.clip(ph.restitution, 1e-3, 0.999))
        # integrated in SUBSTEPS per output step; while a contact spring is compressed in
        # SPRING_SUBSTEPS, or more where its period needs them (250 steps a period; the shuttle
        # and the arm's tip on either side of the spring)
        arm_inertia = np.tile(self.arm_inertia, tiles)
        tip_mass = (arm_inertia + ph.rotor_inertia_kgm2) / np.tile(self.arm, tiles) ** 2
        # the contact's damper for e between the shuttle and the struck tip (their reduced
        # mass: the tip of a direct drive is a tenth of the shuttle)
        reduced_mass = m * tip_mass / (m + tip_mass)
        contact = np.where(np.isfinite(stiffness), stiffness, 0.0)
        damping = 2 * zeta * np.sqrt(contact * reduced_mass)
        omega = np.sqrt(contact / reduced_mass)
        contact_substeps = np.maximum(SPRING_SUBSTEPS, np.ceil(omega * STEP_S / OMEGA_STEP))
        # a torsional spring: its damper from the ratio of the mode the encoder sees after the
        # strike, motor against arm with the shuttle on it (J_a + m r^2); steps fine enough for
        # that mode (TORSION_STEP of its oscillation a step) and stable without the shuttle
        # (TORSION_STABLE radians a step)
        torsion = np.asarray(ph.torsion_nm_per_rad, dtype=float)
        loaded = np.tile(self.loaded_inertia, tiles)
        reduced = ph.rotor_inertia_kgm2 * loaded / (ph.rotor_inertia_kgm2 + loaded)
        torsion_damping = 2 * ph.torsion_damping_ratio * np.sqrt(torsion * reduced)
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = 1 / ph.rotor_inertia_kgm2
            mode = np.sqrt(torsion * (inverse + 1 / loaded)) / TORSION_STEP
            free = np.sqrt(torsion * (inverse + 1 / arm_inertia)) / TORSION_STABLE
            # (and its damper, explicit: its decay rate times the step below 1)
            decay = torsion_damping * (inverse + 1 / arm_inertia)
        fine = np.where(torsion > 0, np.ceil(np.maximum.reduce([mode, free, decay]) * STEP_S), 0.0)
        substeps = np.maximum(float(SUBSTEPS), fine)
        contact_substeps = np.maximum(contact_substeps, substeps)
        columns = [
            m,
            *(np.tile(a, tiles) for a in (self.arm, self.k_s, self.theta_d, self.arm_inertia)),
            *(np.tile(a, tiles) for a in (self.q0, self.y0, self.v0)),
            ph.rotor_inertia_kgm2,
            ph.viscous_nms_per_rad,
            ph.coulomb_nm,
            ph.static_nm,
            ph.torque_offset_nm,
            ph.weight_torque_nm,
            ph.restitution,
            stiffness,
            damping,
            ph.rail_friction_n,
            ph.backlash_rad,
            ph.encoder_step_rad,
            substeps,
            contact_substeps,
            ph.torque_limit_nm,
            ph.cogging_nm,
            ph.cogging_periods,
            ph.cogging_phase_rad,
            torsion,
            torsion_damping,
            ph.backlash_start,
            np.tile(self.own_steps if shortcuts else np.zeros_like(self.own_steps), tiles),
        ]
        out_q = np.empty((n, steps))
        out_y = np.empty((n, steps))
        impact(STEP_S, steps, np.stack(columns, axis=1).astype(float), out_q, out_y)
        out_y -= np.tile(self.tip0, tiles)[:, None]  # as recorded: above the tip at rest
        return np.arange(steps, dtype=float) * STEP_S, out_q, out_y
