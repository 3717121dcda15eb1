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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.drop_kernel import impact
from transparency_ros.analysis.discrepancy.effects import drifted, pinned
from transparency_ros.analysis.discrepancy.model import GRAVITY, FloatArray, read_spec
from transparency_ros.analysis.discrepancy.problem import (
    Trace,
    position_noise,
    spectrum_peak,
)
from transparency_ros.core.config import finite_number, get_actuator, load_drop_test
from transparency_ros.core.contact_model import restitution_damping_ratio
from transparency_ros.core.errors import ConfigError, ModelError

BoolArray = npt.NDArray[np.bool_]
# the simulated trajectories are sampled every STEP_S and integrated in SUBSTEPS per sample
# (collisions and reversals are located within a step; 25 us gives the same held-out error as
# 10 us to within half the noise floor of these rigs)
STEP_S = 1e-4
SUBSTEPS = 4
SPRING_SUBSTEPS = 10  # the contact's onset and end fall within a step
OMEGA_STEP = 0.025  # radians of the contact spring's oscillation per step
LEAD_S = 0.003  # the impact piece starts this long before the recorded contact
AFTER_S = 0.25  # and lasts this long after it
PHASES = ("before_contact", "impact", "deflection", "rebound", "reversal", "stuck")


# ----------------------------------------------------------------------------- data


@dataclass(frozen=True)
class DropTrial:
    """One drop-test bag, times in seconds from the bag's first sample."""

    name: str
    actuator: str
    t_q: FloatArray  # encoder samples
    q: FloatArray
    t_h: FloatArray  # DAQ samples
    height: FloatArray  # shuttle contact face above the tip at rest [m]
    force: FloatArray  # load cell [N]
    theta_d: float
    k_s: float
    mass_kg: float
    arm_m: float
    arm_inertia_kgm2: float
    contact_s: float  # first load-cell sample above the threshold
    contact_end_s: float  # first sample after it back below the threshold
    release_s: float
    held_height_m: float
    # the fall's parabola h = c2 (t - mid)^2 + c1 (t - mid) + c0 as (c2, c1, c0, mid)
    fall: tuple[float, float, float, float] | None = None

    @property
    def start_s(self) -> float:
        return self.contact_s - LEAD_S

    @property
    def end_s(self) -> float:
        return min(self.contact_s + AFTER_S, float(self.t_q[-1]), float(self.t_h[-1]))


def load_drop_trial(path: str | Path) -> DropTrial:
    """A drop-test bag (README, "Bag contract") as a :class:`DropTrial`."""
    from transparency_ros.analysis.drop_eval import CUSTOM_KEYS  # noqa: PLC0415
    from transparency_ros.bag.errors import BagReadError  # noqa: PLC0415
    from transparency_ros.bag.reader import joint_series, open_bag, scalar_series  # noqa: PLC0415

    p = Path(path)
    with open_bag(p) as bag:
        custom = bag.require_custom(*CUSTOM_KEYS, "transparency.arm_inertia_kgm2")
        numbers: dict[str, float] = {}
        for key in (*CUSTOM_KEYS[1:], "transparency.arm_inertia_kgm2"):
            try:
                numbers[key] = float(custom[key])
            except ValueError:
                numbers[key] = math.nan
        bad = {k: custom[k] for k, v in numbers.items() if not math.isfinite(v)}
        if bad:
            raise BagReadError(f"{p}: custom_data must hold finite numbers, got {bad}")
        states = joint_series(bag, "/joint_states")
        force = scalar_series(
            bag, "/load_cell", "geometry_msgs/msg/WrenchStamped", "wrench.force.z"
        )
        height = scalar_series(bag, "/shuttle/height", "geometry_msgs/msg/PointStamped", "point.z")
        theta_d = 0.0
        if "/joint_commands" in bag.topics:
            commands = joint_series(bag, "/joint_commands")
            finite = commands.position[np.isfinite(commands.position)]
            theta_d = float(finite[-1]) if finite.size else 0.0
    keep = np.isfinite(states.position)
    t0_ns = int(min(states.stamp_ns[0], height.stamp_ns[0]))  # exact; seconds from there on
    t_q, q = states.seconds(t0_ns)[keep], states.position[keep]
    t_h, h = height.seconds(t0_ns), height.value
    f = np.interp(t_h, force.seconds(t0_ns), force.value)
    threshold = load_drop_test().contact_force_threshold_n
    above = np.nonzero(f > threshold)[0]
    if above.size == 0:
        raise BagReadError(f"{p}: /load_cell never exceeds {threshold} N: no contact to analyse")
    contact = float(t_h[above[0]])
    below = np.nonzero((t_h > contact) & (f <= threshold))[0]
    contact_end = float(t_h[below[0]]) if below.size else contact + 0.02
    if q.size < 20 or np.count_nonzero(t_q < contact - LEAD_S) < 5:
        raise BagReadError(f"{p}: /joint_states has too few samples before contact")
    held, release, fall = _release(t_h, h, contact, p)
    return DropTrial(
        name=f"{p.parent.name}/{p.name}",
        actuator=custom["transparency.actuator"],
        t_q=t_q,
        q=q,
        t_h=t_h,
        height=h,
        force=f,
        theta_d=theta_d,
        k_s=numbers["transparency.k_s"],
        mass_kg=numbers["transparency.shuttle_mass_kg"],
        arm_m=numbers["transparency.arm_length_m"],
        arm_inertia_kgm2=numbers["transparency.arm_inertia_kgm2"],
        contact_s=contact,
        contact_end_s=contact_end,
        release_s=release,
        held_height_m=held,
        fall=fall,
    )


def _release(
    t: FloatArray, h: FloatArray, contact: float, where: Path
) -> tuple[float, float, tuple[float, float, float, float] | None]:
    """(held height, release time, the fall's parabola). The fall under any constant force is
    a parabola h0 - a/2 (t - t_r)^2, so its vertex is the release: a quadratic fitted to the
    whole fall (up to the impact piece) gives t_r without assuming g or a rail without
    friction, and the shuttle's state at the impact piece's start from all of the fall."""
    first = t < t[0] + 0.02
    held = float(np.median(h[first]))
    noise = float(np.median(np.abs(np.diff(h[first], n=2)))) / 0.6745 / math.sqrt(6)
    gone = np.nonzero((h < held - max(6 * noise, 1e-4)) & (t < contact))[0]
    if gone.size == 0 or np.count_nonzero(first) < 10:
        raise ModelError(f"{where}: no hold before the release in /shuttle/height")
    fit = (t >= t[gone[0]]) & (t < contact - LEAD_S)
    if np.count_nonzero(fit) < 10:
        return held, float(t[gone[0]]), None
    mid = float(np.mean(t[fit]))
    c2, c1, c0 = (float(c) for c in np.polyfit(t[fit] - mid, h[fit], 2))
    if c2 >= 0:
        raise ModelError(f"{where}: the shuttle does not fall after the release")
    return held, mid - c1 / (2 * c2), (c2, c1, c0, mid)


# ----------------------------------------------------------------------------- physics


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
    delay_s: FloatArray | float = 0.0
    encoder_step_rad: FloatArray | float = 0.0

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
        self.trials = list(trials)
        self.mass = np.array([t.mass_kg for t in trials])
        self.arm = np.array([t.arm_m for t in trials])
        self.arm_inertia = np.array([t.arm_inertia_kgm2 for t in trials])
        self.k_s = np.array([t.k_s for t in trials])
        self.theta_d = np.array([t.theta_d for t in trials])
        self.q0 = np.array([_rest_position(t) for t in trials])
        y0, v0 = zip(*(_shuttle_state(t) for t in trials), strict=True)
        self.y0, self.v0 = np.array(y0), np.array(v0)
        self.duration = max(t.end_s - t.start_s for t in trials) + 0.03

    def run(self, ph: DropPhysics, tiles: int = 1) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(time from each trial's start, motor position, shuttle height), (rows, steps): the
        trials ``tiles`` times over, row ``j * n_trials + i`` with physics row alike."""
        n = len(self.trials) * tiles
        ph = ph.rows(n)
        steps = math.ceil(self.duration / STEP_S) + 1
        m = np.tile(self.mass, tiles)
        stiffness = np.asarray(ph.stiffness_n_per_m, dtype=float)
        zeta = restitution_damping_ratio(np.clip(ph.restitution, 1e-3, 0.999))
        damping = np.where(np.isfinite(stiffness), 2 * zeta * np.sqrt(stiffness * m), 0.0)
        # integrated in SUBSTEPS per output step; while a contact spring is compressed in
        # SPRING_SUBSTEPS, or more where its period needs them (250 steps a period; the shuttle
        # and the arm's tip on either side of the spring)
        tip_mass = (np.tile(self.arm_inertia, tiles) + ph.rotor_inertia_kgm2) / np.tile(
            self.arm, tiles
        ) ** 2
        omega = np.sqrt(np.where(np.isfinite(stiffness), stiffness, 0.0) * (1 / m + 1 / tip_mass))
        contact_substeps = np.maximum(SPRING_SUBSTEPS, np.ceil(omega * STEP_S / OMEGA_STEP))
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
            np.full(n, SUBSTEPS),
            contact_substeps,
        ]
        out_q = np.empty((n, steps))
        out_y = np.empty((n, steps))
        impact(STEP_S, steps, np.stack(columns, axis=1).astype(float), out_q, out_y)
        return np.arange(steps, dtype=float) * STEP_S, out_q, out_y


def _rest_position(trial: DropTrial) -> float:
    before = trial.q[trial.t_q < trial.start_s]
    return float(np.median(before[-10:]))


def _shuttle_state(trial: DropTrial) -> tuple[float, float]:
    """Height and velocity at the impact piece's start: from the fall's parabola, or a
    quadratic over the 15 ms before when the fall is too short to fit."""
    if trial.fall is not None:
        c2, c1, c0, mid = trial.fall
        dt = trial.start_s - mid
        return c2 * dt * dt + c1 * dt + c0, 2 * c2 * dt + c1
    sel = (trial.t_h >= trial.start_s - 0.015) & (trial.t_h < trial.start_s)
    if np.count_nonzero(sel) < 5:
        raise ModelError(f"{trial.name}: too few shuttle samples before contact")
    coef = np.polyfit(trial.t_h[sel] - trial.start_s, trial.height[sel], 2)
    return float(coef[2]), float(coef[1])


# ----------------------------------------------------------------------------- effects


@dataclass
class DropEffect:
    name: str
    param_names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    fittable: bool = True
    discrete_choices: int = 0

    def initial(self, problem: DropProblem) -> FloatArray:
        return np.array([(lo + hi) / 2 for lo, hi in zip(self.lower, self.upper, strict=True)])

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        raise NotImplementedError

    def meaningful(self, p: FloatArray) -> bool:
        """A fit held at a bound of its plausible range (a restitution of 0.95, a 3 degree
        backlash, a rigid contact) stands in for something else: it names nothing."""
        return not pinned(p, self.lower, self.upper)

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        return {}


class DropDrift(DropEffect):
    def __init__(self) -> None:
        super().__init__(
            "parameter_drift",
            ("reflected_inertia_scale", "viscous_scale", "coulomb_scale"),
            (0.2, 0.0, 0.0),
            (5.0, 5.0, 5.0),
        )

    def initial(self, problem: DropProblem) -> FloatArray:
        return np.ones(3)

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        return replace(
            ph,
            rotor_inertia_kgm2=ph.rotor_inertia_kgm2 * p[0],
            viscous_nms_per_rad=ph.viscous_nms_per_rad * p[1],
            coulomb_nm=ph.coulomb_nm * p[2],
            static_nm=np.maximum(ph.static_nm, ph.coulomb_nm * p[2]),
        )

    def meaningful(self, p: FloatArray) -> bool:
        return drifted(p) and not pinned(p, self.lower, self.upper)


class SetPhysics(DropEffect):
    """An effect that sets one value of the physics to its single parameter."""

    def __init__(self, name: str, param: str, lower: float, upper: float, target: str) -> None:
        super().__init__(name, (param,), (lower,), (upper,))
        self.target = target

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        changes: dict[str, Any] = {self.target: float(p[0])}
        return replace(ph, **changes)


class DropStiction(DropEffect):
    def __init__(self) -> None:
        super().__init__("stiction", ("static_nm",), (0.0,), (2.0,))

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        return replace(ph, static_nm=np.maximum(ph.coulomb_nm, float(p[0])))


class ImpactSpeedLoss(SetPhysics):
    """Rail friction: the shuttle arrives slower than free fall."""

    def __init__(self, shuttle_mass_kg: float) -> None:
        super().__init__("impact_speed_loss", "rail_friction_n", 0.0, 5.0, "rail_friction_n")
        self.shuttle_mass_kg = shuttle_mass_kg

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        # v^2 = 2 (g - F/m) h: the fraction of the free-fall speed lost at impact
        return {
            "speed_loss_fraction": float(
                1 - math.sqrt(max(0.0, 1 - p[0] / (self.shuttle_mass_kg * GRAVITY)))
            )
        }


class StructuralCompliance(DropEffect):
    """The contact (arm, load cell, shuttle) is a spring: the collision takes time."""

    def __init__(self) -> None:
        super().__init__("structural_compliance", ("log10_stiffness_n_per_m",), (3.0,), (6.0,))

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        return replace(ph, stiffness_n_per_m=float(10 ** p[0]))

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        return {"stiffness_n_per_m": float(10 ** p[0])}


class DropQuantization(DropEffect):
    def __init__(self) -> None:
        super().__init__("quantization", ("step_rad",), (1e-7,), (0.1,), fittable=False)

    def initial(self, problem: DropProblem) -> FloatArray:
        steps = np.concatenate([np.abs(np.diff(t.q)) for t in problem.fit_trials])
        nonzero = steps[steps > 1e-12]
        return np.array([float(np.min(nonzero)) if nonzero.size else 1e-6])

    def apply(self, ph: DropPhysics, p: FloatArray, problem: DropProblem) -> DropPhysics:
        return replace(ph, encoder_step_rad=float(p[0]))


def drop_library(shuttle_mass_kg: float) -> list[DropEffect]:
    return [
        DropDrift(),
        SetPhysics("torque_offset", "offset_nm", -2.0, 2.0, "torque_offset_nm"),
        # the shuttle's weight on the arm, m_s g r cos(theta), while they touch
        SetPhysics("payload_gravity", "mgl_nm", 0.0, 5.0, "weight_torque_nm"),
        DropStiction(),
        SetPhysics("restitution", "coefficient", 0.0, 0.95, "restitution"),
        ImpactSpeedLoss(shuttle_mass_kg),
        StructuralCompliance(),
        SetPhysics("backlash", "backlash_rad", 0.0, 0.05, "backlash_rad"),
        SetPhysics("sensor_delay", "delay_s", 0.0, 0.02, "delay_s"),
        DropQuantization(),
    ]


# ----------------------------------------------------------------------------- problem


class _Set:
    """The compared samples of some trials: fall heights and impact-piece samples."""

    def __init__(self, trials: Sequence[DropTrial]) -> None:
        self.trials = list(trials)
        self.sim = DropSimulator(trials)
        self.fall: list[tuple[FloatArray, FloatArray]] = []  # (t since release, height)
        self.q: list[tuple[FloatArray, FloatArray]] = []  # (t since piece start, q)
        self.h: list[tuple[FloatArray, FloatArray]] = []  # (t since piece start, height)
        for t in trials:
            fall = (t.t_h > t.release_s) & (t.t_h < t.start_s)
            self.fall.append((t.t_h[fall][::10] - t.release_s, t.height[fall][::10]))
            sel = (t.t_q >= t.start_s) & (t.t_q <= t.end_s)
            self.q.append((t.t_q[sel] - t.start_s, t.q[sel]))
            sel = (t.t_h >= t.start_s) & (t.t_h <= t.end_s)
            self.h.append((t.t_h[sel][::10] - t.start_s, t.height[sel][::10]))

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
            parts = []
            for i, trial in enumerate(self.trials):
                row, r = j * n + i, trial.arm_m
                # the fall: free fall from the hold, braked by the rail
                t_f, h_f = self.fall[i]
                a = GRAVITY - rail_n[row] / trial.mass_kg
                parts.append((trial.held_height_m - 0.5 * a * t_f**2 - h_f) / r)
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
        mass = float(np.mean([t.mass_kg for t in trials]))
        self._candidates = list(candidates) if candidates is not None else drop_library(mass)
        self.nominal = {
            k: v for k, v in nominal.as_dict().items() if k.startswith(f"{self.actuator}.")
        }
        self.split = {
            "fit": [t.name for t in self.fit_trials],
            "heldout": [t.name for t in self.held_trials],
        }

    def physics(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray], n: int
    ) -> DropPhysics:
        a = self.actuator
        ones = np.ones(n)
        ph = DropPhysics(
            rotor_inertia_kgm2=ones * self.model.reflected_inertia_kgm2[a],
            viscous_nms_per_rad=ones * self.model.viscous_nms_per_rad[a],
            coulomb_nm=ones * self.model.coulomb_nm[a],
            static_nm=ones * self.model.coulomb_nm[a],
        )
        for effect, p in zip(effects, params, strict=True):
            ph = effect.apply(ph, p, self)
        return ph

    def candidates(self) -> list[DropEffect]:
        return list(self._candidates)

    def initial(self, effect: DropEffect) -> FloatArray:
        return effect.initial(self)

    def error(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray], held: bool
    ) -> FloatArray:
        s = self.held if held else self.fit
        return s.error(self.physics(effects, params, len(s.trials)))

    def error_sets(
        self,
        effects: Sequence[DropEffect],
        param_sets: Sequence[Sequence[FloatArray]],
        held: bool,
    ) -> list[FloatArray]:
        s = self.held if held else self.fit
        n = len(s.trials)
        return s.error_many([self.physics(effects, params, n) for params in param_sets])

    def phases(self) -> dict[str, BoolArray]:
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

    def noise_floor(self) -> float:
        """RMS error sensor noise alone gives: encoder (quantization) and potentiometer noise,
        weighted by how many samples of each are compared."""
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
        n_q = sum(q.size for _, q in self.fit.q)
        n_h = sum(h.size for _, h in self.fit.h) + sum(h.size for _, h in self.fit.fall)
        return float(math.sqrt((n_q * q_noise**2 + n_h * h_noise**2) / max(1, n_q + n_h)))

    def residual_peak_hz(
        self, effects: Sequence[DropEffect], params: Sequence[FloatArray]
    ) -> float:
        """Where the held-out encoder residual after contact has most power (uniformly
        resampled at 1 kHz)."""
        ph = self.physics(effects, params, len(self.held_trials))
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
        t_sim, q_nom, _ = self.held.sim.run(self.physics([], [], len(self.held_trials)))
        ph = self.physics(effects, params, len(self.held_trials))
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


def _phase_masks(trial: DropTrial, t: FloatArray) -> dict[str, BoolArray]:
    """Phase of each time ``t`` of a trial, from its recorded data: before contact; the first
    impact (load cell above threshold); then by the arm's recorded motion: away from rest
    (deflection), back towards it (rebound), within 3 ms of a turn (reversal), or stuck."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    rest = _rest_position(trial)
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
