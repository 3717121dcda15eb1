"""Candidate effects on a robot (issue 27), each acting where its physics acts: on the command
path before the joint (``command_delay`` of the whole robot, a joint's ``torque_gain`` and
``torque_saturation``), or as a torque the joint's model leaves out (``torque_offset``,
``coulomb_friction``, ``viscous_friction``, ``cogging``, a link's ``payload`` and
``parameter_drift``). ``sensor_delay`` (the positions recorded late) shifts the two sides of the
balance against each other exactly as ``command_delay`` does: the balance cannot tell them apart,
and the report says so (explained alike).

Every effect but the delay belongs to one joint (or the link that joint moves) and is named
``kind[joint]``: the discovery loop (:mod:`discover`) treats effects of one name as variants of
one another, and a joint's gain is not a variant of another joint's. ``kind`` and ``joint`` are
what the JSON reports (``joint`` None: the whole robot).

The problem (:class:`~transparency_ros.analysis.discrepancy.robot.RobotProblem`) hands each
effect a :class:`Context` of one run: the command on a wide grid before smoothing, the joints'
state on the compared grid, the torque regressor and the nominal parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from transparency_ros.analysis.discrepancy.effects import pinned, strongest_wave
from transparency_ros.analysis.discrepancy.model import FloatArray

MOST_DELAY_S = 0.03  # a command acting up to this late
GAIN_RANGE = (0.2, 5.0)  # a torque constant this far off at most
PAYLOAD_MOST = 2.0  # a payload up to this times the mass the joint moves (its subtree)
PAYLOAD_LEAST_KG = 0.1  # (the bound on the payload of a very light link)
COM_MOST_M = 2.0
STRIBECK_RAD_S = (0.01, 2.0)  # the speeds a Stribeck fall-off is looked for between


@dataclass
class Context:
    """What an effect may change in one run's torque balance."""

    v: FloatArray  # (samples, joints) joint speeds on the compared grid
    a: FloatArray  # (samples, joints) joint accelerations there
    sliding: FloatArray  # (samples, joints) the Coulomb law's tanh(q' / eps), smoothed
    regressor: FloatArray  # (samples, joints, 10 * links): tau = Y pi
    nominal: FloatArray  # (10 * links,) the nominal inertial parameters
    # (joint, cycles per revolution) -> (samples, 2): sin and cos of cycles * q of the joint,
    # computed on the full grid and low-passed as the balance is
    wave: Callable[[int, int], FloatArray]
    # (joint, Stribeck speed v_s) -> (samples,): exp(-(q'/v_s)^2) tanh(q'/eps) of the joint,
    # computed on the full grid and low-passed as the balance is
    stribeck: Callable[[int, float], FloatArray]


class RobotEffect:
    """One candidate: ``kind`` on ``joint`` (an index into the model's joints; None: the whole
    robot), parameters in SI units with bounds and the value that means no effect (``null``;
    NaN: any value). ``stage`` says where it acts: ``delay`` (when the command acts),
    ``command`` (what reaches the joint, per joint, before the smoothing the balance shares)
    or ``torque`` (added to the model's side of the balance)."""

    stage = "torque"
    fittable = True
    discrete_choices = 0
    rigid_body: ClassVar[bool] = False  # a change of the links' inertial parameters (inertial)

    def __init__(
        self,
        kind: str,
        joint: int | None,
        joint_name: str | None,
        *,
        param_names: tuple[str, ...],
        lower: tuple[float, ...],
        upper: tuple[float, ...],
        null: tuple[float, ...],
        start: tuple[float, ...],
    ) -> None:
        self.kind = kind
        self.joint = joint
        self.joint_name = joint_name
        self.name = kind if joint_name is None else f"{kind}[{joint_name}]"
        self.param_names = param_names
        self.lower = lower
        self.upper = upper
        self.null = null
        self.start = np.array(start, dtype=float)

    def meaningful(self, p: FloatArray) -> bool:
        """A fit held at a bound of its range stands in for something it cannot be (the
        ranges of signed terms are symmetric: their sizes are checked)."""
        return not self.pinned_by_refit(p)

    def pinned_by_refit(self, p: FloatArray) -> bool:
        """Held at a bound of its range (see meaningful): where a joint refit does this to
        an effect named before, the step is not meaningful (``steps.driven_to_bound``)."""
        return pinned(np.abs(p), self.lower, self.upper)

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        return {}

    def delay(self, p: FloatArray) -> float:
        return 0.0

    def command(self, tau: FloatArray, p: FloatArray) -> FloatArray:
        """The torque reaching the joints, (samples, joints), from the command ``tau``."""
        return tau

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray | None:
        """The torque the model leaves out, (samples, joints); None: none."""
        return None

    def inertial(self, p: FloatArray, nominal: FloatArray) -> FloatArray | None:
        """The change of the links' inertial parameters (Pinocchio's 10 per link, as
        ``nominal``) this effect is, for a model that carries it (a detector's); None: the
        effect is not one (its torque is not the rigid body's)."""
        return None

    def armature(self, p: FloatArray) -> float | None:
        """What this effect adds to its joint's armature [kg m^2], for a model that carries
        it; None: the effect is not a rotor's inertia."""
        return None


class CommandDelay(RobotEffect):
    """The motors act on the command ``delay_s`` late (the current loop, the bus); negative:
    before its stamp, i.e. the command's stamps are late against the positions' (a recorder
    that stamps on publishing, two clocks). The real pendubot's balance is closest at about
    -6 ms against its URDF: a delay concealed in it shows as a shift from there, so the range
    is signed.

    ``kind="sensor_delay"`` (0 to 30 ms): the positions are recorded late (an encoder's filter,
    the bus). In the torque balance that is this shift exactly (the states compared with the
    command ``delay_s`` earlier); it is its own candidate so that a finding of either names
    the other as explained alike."""

    stage = "delay"

    def __init__(self, kind: str = "command_delay") -> None:
        signed = kind == "command_delay"
        super().__init__(kind, None, None, **_spec(
            ("delay_s",), (-MOST_DELAY_S if signed else 0.0,), (MOST_DELAY_S,), (0.0,),
            (0.0 if signed else 0.005,)))  # fmt: skip

    def delay(self, p: FloatArray) -> float:
        return float(p[0])


def _spec(*values: tuple[Any, ...]) -> dict[str, Any]:
    """RobotEffect's keywords from (names, lower, upper, null, start) in that order."""
    return dict(zip(("param_names", "lower", "upper", "null", "start"), values, strict=True))


class _JointEffect(RobotEffect):
    def __init__(self, kind: str, joint: int, name: str, *spec: tuple[Any, ...]) -> None:
        super().__init__(kind, joint, name, **_spec(*spec))
        self.index = joint  # (``joint`` narrowed: every joint effect has one)

    def _one(self, ctx: Context, column: FloatArray) -> FloatArray:
        out = np.zeros(ctx.v.shape)
        out[:, self.index] = column
        return out


class TorqueGain(_JointEffect):
    """The joint's torque is ``gain`` times its command (a torque constant or gear ratio off)."""

    stage = "command"

    def __init__(self, joint: int, name: str) -> None:
        super().__init__(
            "torque_gain",
            joint,
            name,
            ("gain",),
            (GAIN_RANGE[0],),
            (GAIN_RANGE[1],),
            (1.0,),
            (1.0,),
        )

    def command(self, tau: FloatArray, p: FloatArray) -> FloatArray:
        out = tau.copy()
        out[:, self.index] *= p[0]
        return out


class TorqueSaturation(_JointEffect):
    """The joint's torque falls off smoothly towards ``limit_nm``: L tanh(command / L)."""

    stage = "command"

    def __init__(self, joint: int, name: str, largest_nm: float) -> None:
        top = max(largest_nm, 1e-6)
        super().__init__(
            "torque_saturation", joint, name, ("limit_nm",), (0.05 * top,), (3.0 * top,),
            (math.inf,), (top,),
        )  # fmt: skip

    def command(self, tau: FloatArray, p: FloatArray) -> FloatArray:
        out = tau.copy()
        limit = float(p[0])
        out[:, self.index] = limit * np.tanh(tau[:, self.index] / limit)
        return out

    def meaningful(self, p: FloatArray) -> bool:
        # held at the top of its range it is no saturation the recording shows
        return bool(p[0] < 0.99 * self.upper[0]) and super().meaningful(p)


class TorqueOffset(_JointEffect):
    def __init__(self, joint: int, name: str, largest_nm: float) -> None:
        top = max(largest_nm, 1e-6)
        super().__init__(
            "torque_offset", joint, name, ("offset_nm",), (-top,), (top,), (0.0,), (0.0,)
        )

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return self._one(ctx, np.full(ctx.v.shape[0], float(p[0])))


class CoulombFriction(_JointEffect):
    """Coulomb friction the model leaves out (negative: the model has too much)."""

    def __init__(self, joint: int, name: str, largest_nm: float) -> None:
        top = max(largest_nm, 1e-6)
        super().__init__(
            "coulomb_friction", joint, name, ("coulomb_nm",), (-top,), (top,), (0.0,), (0.0,)
        )

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return self._one(ctx, float(p[0]) * ctx.sliding[:, self.index])


class ViscousFriction(_JointEffect):
    """Viscous friction the model leaves out (negative: the model has too much)."""

    def __init__(self, joint: int, name: str, most: float) -> None:
        top = max(most, 1e-6)
        super().__init__(
            "viscous_friction",
            joint,
            name,
            ("viscous_nms_per_rad",),
            (-top,),
            (top,),
            (0.0,),
            (0.0,),
        )

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return self._one(ctx, float(p[0]) * ctx.v[:, self.index])


class Cogging(_JointEffect):
    """A torque ripple A sin(N q + phi) of the joint's motor, N cycles per revolution of the
    joint (picked from the fit runs' residual of the joint's row with the effects found so far,
    ``scan``)."""

    def __init__(self, joint: int, name: str, largest_nm: float) -> None:
        top = max(largest_nm, 1e-6)
        super().__init__(
            "cogging", joint, name, ("amplitude_nm", "phase_rad"), (0.0, -math.pi),
            (top, math.pi), (0.0, math.nan), (0.0, 0.0),
        )  # fmt: skip
        self.cycles_per_rev = 2  # until ``choose`` picks it

    def extra_parameters(self, p: FloatArray) -> dict[str, float]:
        return {"periods_per_rev": float(self.cycles_per_rev)}

    def scan(self, problem: Any, effects: list[Any], params: list[FloatArray]) -> FloatArray:
        """The start of a fit against ``effects`` (fitting.fit_candidate's hook): the period
        scanned on the problem's residual with them (``wave_start``)."""
        return np.asarray(problem.wave_start(self, effects, params), dtype=float)

    def choose(self, waves: Callable[[int], FloatArray], residual: FloatArray) -> FloatArray:
        """Pick N where sin / cos of N q explain most of ``residual`` (the joint's row,
        stacked over the fit runs; ``waves(N)`` stacks the waves alike); the start there."""
        self.cycles_per_rev, amplitude, phase = strongest_wave(waves, residual)
        return np.array([min(amplitude, self.upper[0]), phase])

    def meaningful(self, p: FloatArray) -> bool:
        # the phase has no bound that means anything: only the amplitude is checked
        return not pinned(np.abs(p[:1]), self.lower[:1], self.upper[:1])

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        # A sin(N q + phi) = A cos(phi) sin(N q) + A sin(phi) cos(N q)
        w = ctx.wave(self.index, self.cycles_per_rev)
        amplitude, phase = float(p[0]), float(p[1])
        return self._one(ctx, amplitude * (math.cos(phase) * w[:, 0] + math.sin(phase) * w[:, 1]))


class Stiction(_JointEffect):
    """Friction above the Coulomb level near rest, falling off with speed (Stribeck):
    ``static_nm`` exp(-(q' / v_s)^2) sign(q'), ``stribeck_rad_s`` = v_s (negative: the model
    has too much)."""

    def __init__(self, joint: int, name: str, largest_nm: float) -> None:
        top = max(largest_nm, 1e-6)
        super().__init__(
            "stiction", joint, name, ("static_nm", "stribeck_rad_s"), (-top, STRIBECK_RAD_S[0]),
            (top, STRIBECK_RAD_S[1]), (0.0, math.nan), (0.0, 0.2),
        )  # fmt: skip

    def meaningful(self, p: FloatArray) -> bool:
        # the speed means nothing without a level: the level is checked, and the speed off its
        # bounds (held there it stands in for a Coulomb friction, or for noise)
        return not pinned(np.abs(p[:1]), self.lower[:1], self.upper[:1]) and not pinned(
            p[1:], self.lower[1:], self.upper[1:]
        )

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return self._one(ctx, float(p[0]) * ctx.stribeck(self.index, float(p[1])))


class Payload(_JointEffect):
    """A point mass ``mass_kg`` fixed to the link the joint moves, its weight and inertia
    through the link's regressor columns. Where it sits is fitted in the plane through the
    joint's frame across its axis of rotation (``com_u_m``, ``com_w_m`` along two directions
    of that plane, in the link's frame): an offset along the axis changes no torque about a
    parallel axis, and fitted free it wandered to its bound (the payload was then refused as
    pinned on a planar robot). ``axis`` None (a prismatic joint): all three coordinates."""

    rigid_body = True

    def __init__(
        self, joint: int, name: str, moved_kg: float, axis: FloatArray | None = None
    ) -> None:
        # (heavier than twice what the joint moves, it is no payload but a stand-in: a mass of
        # 13 kg a few millimetres off a 0.5 kg link's axis, a pure weight torque, on a robot
        # whose concealed payload was 0.46 kg on the next link)
        most = max(PAYLOAD_MOST * moved_kg, PAYLOAD_LEAST_KG)
        if axis is None:
            self.frame = np.eye(3)
            names: tuple[str, ...] = ("com_x_m", "com_y_m", "com_z_m")
        else:
            a = np.asarray(axis, dtype=float) / float(np.linalg.norm(axis))
            u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            self.frame = np.stack([u, np.cross(a, u)], axis=1)  # (3, 2): the plane's directions
            names = ("com_u_m", "com_w_m")
        k = len(names)
        super().__init__(
            "payload", joint, name, ("mass_kg", *names), (0.0, *[-COM_MOST_M] * k),
            (most, *[COM_MOST_M] * k), (0.0, *[math.nan] * k), (0.05 * most, *[0.0] * k),
        )  # fmt: skip

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return np.asarray(ctx.regressor @ self.inertial(p, ctx.nominal), dtype=float)

    def inertial(self, p: FloatArray, nominal: FloatArray) -> FloatArray:
        m, c = float(p[0]), self.frame @ np.asarray(p[1:], dtype=float)
        r2 = float(c @ c)
        # a point mass's 10 parameters: m, m c, and its inertia about the link's origin
        # (Pinocchio's order Ixx, Ixy, Iyy, Ixz, Iyz, Izz)
        inertia = m * (r2 * np.eye(3) - np.outer(c, c))
        out = np.zeros(nominal.shape)
        k = 10 * self.index
        out[k : k + 10] = np.r_[m, m * c, inertia[0, 0], inertia[0, 1], inertia[1, 1],
                                inertia[0, 2], inertia[1, 2], inertia[2, 2]]  # fmt: skip
        return out


class ParameterDrift(_JointEffect):
    """A term of the link's inertial parameters is ``scale`` times the model's: its mass and
    first moments together (``mass_scale``: its weight, as a payload spread like the link),
    or its rotational inertia about the joint's frame (``inertia_scale``: a URDF giving
    inertias about the wrong point). Both are named ``parameter_drift[joint]``, variants."""

    rigid_body = True

    TERMS: ClassVar[dict[str, slice]] = {"mass_scale": slice(0, 4), "inertia_scale": slice(4, 10)}

    def __init__(self, joint: int, name: str, term: str) -> None:
        super().__init__("parameter_drift", joint, name, (term,), (0.2,), (5.0,), (1.0,), (1.0,))
        self.term = self.TERMS[term]

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return np.asarray(ctx.regressor @ self.inertial(p, ctx.nominal), dtype=float)

    def inertial(self, p: FloatArray, nominal: FloatArray) -> FloatArray:
        out = np.zeros(nominal.shape)
        part = slice(10 * self.index + self.term.start, 10 * self.index + self.term.stop)
        out[part] = (float(p[0]) - 1.0) * nominal[part]
        return out


class Armature(_JointEffect):
    """The inertia of the joint's rotor, reflected through its gearbox (gr^2 I_rotor), that the
    model lacks (negative: it has too much; at most all of the model's own): a torque
    ``armature_kgm2`` q'' on the joint's own row. A URDF has no place for it (Pinocchio's
    ``armature``; the DFKI lab's parameter file gives it, their URDF does not), and a link's
    inertia does not take it up past the first joint: a link's rotational inertia acts on
    the rows of its joint and every joint above it, a rotor's on its own joint's alone. (On
    the first joint of a chain the two are one term of the balance.)"""

    rigid_body = True  # (carried by a simulator as the model's armature: robot_shooting)

    def __init__(self, joint: int, name: str, nominal_kgm2: float, most_kgm2: float) -> None:
        top = max(most_kgm2, 1e-9)
        super().__init__(
            "armature", joint, name, ("armature_kgm2",), (-max(nominal_kgm2, 0.0),), (top,),
            (0.0,), (0.0,),
        )  # fmt: skip

    def torque(self, ctx: Context, p: FloatArray) -> FloatArray:
        return self._one(ctx, float(p[0]) * ctx.a[:, self.index])

    def armature(self, p: FloatArray) -> float:
        """What the joint's armature gains [kg m^2]."""
        return float(p[0])


class EncoderLattice(_JointEffect):
    """The joint's positions recorded on a lattice of ``step_rad`` (an encoder's counts), read
    off the recordings (:func:`lattice_step`), not fitted: a simulator that leaves the lattice
    out differs from the recordings by it. It changes no torque of the balance (what the
    lattice does there is noise, which the noise floor counts); it is named where it shapes
    the recorded motion: while the joint moves, it moves at most ``LATTICE_COUNTS`` counts
    per 2 ms (``counts``, a median; :func:`lattice_step`). Fine encoders move 3.1-22 counts per
    2 ms on the real pendubot and on the robot zoo's robots, coarse ones (2^9-2^10 counts per
    turn) 0.36-1.4: then it is the lattice, not the model, that limits what the balance sees."""

    stage = "sensor"
    fittable = False
    declared = True
    shown = True

    def __init__(self, joint: int, name: str, step: float, counts: float) -> None:
        super().__init__(
            "quantization", joint, name, ("step_rad",), (0.0,), (math.inf,), (0.0,), (step,)
        )
        self.step, self.counts = step, counts

    def meaningful(self, p: FloatArray) -> bool:
        return True  # read off, not a fit that may stand at a bound of its range

    def measured_interval(self) -> list[tuple[float, float]]:
        # (read off thousands of increments, to within what is taken as on the lattice)
        return [(self.step * (1 - LATTICE_TOLERANCE), self.step * (1 + LATTICE_TOLERANCE))]

    def describe(self) -> str:
        return (
            f"the positions sit on a lattice of {self.step:.4g} rad "
            f"({2 * math.pi / self.step:.0f} counts per turn) and, while the joint moves, by a "
            f"median {self.counts:.2g} count(s) per 2 ms"
        )


# median counts moved per LATTICE_PER_S, at most, for a lattice to be named: the middle (in
# ratio) of the gap between the 14-bit encoders of the real pendubot and of the robot zoo's
# 120 robots (seeds 100-129, 300-329, 400-429, 500-529: 3.1 to 22) and the zoo's 2^9-2^10
# count ones (0.36 to 1.4)
LATTICE_COUNTS = 2.0
LATTICE_PER_S = 0.002  # (the balance's grid step)
LATTICE_TOLERANCE = 0.02  # an increment this close to a multiple of the step is on the lattice
LATTICE_ON = 0.99  # of the nonzero increments on it, for the positions to sit on a lattice
LATTICE_WINDOW_S = 0.05  # windows over which the counts moved are taken
LATTICE_MOVING = 4.0  # counts moved in a window, at least, for the joint to be moving there


def lattice_step(position: FloatArray, sample_s: float) -> tuple[float, float] | None:
    """(step, counts moved per ``LATTICE_PER_S`` while the joint moves) of the lattice the
    positions ``position`` (one joint, recordings concatenated with NaN between them,
    sampled every ``sample_s``) sit on, or None: their smallest increment, where at least
    ``LATTICE_ON`` of the nonzero increments are multiples of it (within
    ``LATTICE_TOLERANCE``), the step refined over all of them. The counts are the median,
    over windows of ``LATTICE_WINDOW_S`` in which the joint moves ``LATTICE_MOVING`` counts
    or more, of the counts it moves there per ``LATTICE_PER_S`` (a time, not a sample: a
    faster recorder moves fewer counts between samples on the same encoder). Taken over every
    sample instead, a joint at rest moves none (a pendubot's elbow held by its friction for
    seconds on a 14-bit encoder was named so)."""
    moved = np.abs(np.diff(position))
    steps = moved[np.isfinite(moved) & (moved > 0)]
    if steps.size < 100:
        return None
    smallest = float(np.min(steps))
    counts = np.round(steps / smallest)
    on = np.abs(steps / smallest - counts) <= LATTICE_TOLERANCE
    if np.mean(on) < LATTICE_ON:
        return None
    step = float(np.sum(steps[on] * counts[on]) / np.sum(counts[on] ** 2))
    window = max(1, round(LATTICE_WINDOW_S / sample_s))
    per_window = np.abs(np.diff(position[::window])) / step
    moving = per_window[np.isfinite(per_window) & (per_window >= LATTICE_MOVING)]
    if moving.size == 0:
        return None
    return step, float(np.median(moving)) * LATTICE_PER_S / (window * sample_s)


def library(
    joints: tuple[str, ...],
    largest_nm: FloatArray,
    fastest: FloatArray,
    axes: list[FloatArray | None] | None = None,
    moved_kg: FloatArray | None = None,
    *,
    rotors: tuple[FloatArray, FloatArray] | None = None,
) -> list[Any]:
    """Every candidate for a robot with ``joints``, whose torques (command or model) reach
    ``largest_nm`` and speeds ``fastest`` [rad/s] (the bounds of the torques' sizes); ``axes``:
    each joint's axis of rotation in its link's frame (None: a prismatic joint, or unknown);
    ``moved_kg``: the mass each joint moves (its links and all after them; the payload's
    bound); ``rotors``: each joint's armature in the model [kg m^2] and the acceleration
    its motion stays under [rad/s^2] (the armature's bound: a rotor whose torque there
    reaches the joint's largest; None: no armature candidate)."""
    out: list[Any] = [CommandDelay(), CommandDelay("sensor_delay")]
    for j, name in enumerate(joints):
        top = float(largest_nm[j])
        out += [
            TorqueGain(j, name),
            TorqueSaturation(j, name, top),
            TorqueOffset(j, name, top),
            CoulombFriction(j, name, top),
            Stiction(j, name, top),
            ViscousFriction(j, name, top / max(float(fastest[j]), 1e-3)),
            Cogging(j, name, top),
            Payload(
                j,
                name,
                math.inf if moved_kg is None else float(moved_kg[j]),
                None if axes is None else axes[j],
            ),
            ParameterDrift(j, name, "mass_scale"),
            ParameterDrift(j, name, "inertia_scale"),
        ]
        if rotors is not None:
            nominal, brisk = rotors
            out.append(Armature(j, name, float(nominal[j]), top / max(float(brisk[j]), 1e-3)))
    return out


__all__ = ["Context", "RobotEffect", "library"]
