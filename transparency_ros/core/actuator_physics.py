"""The actuator's physics, output-referred: the one implementation every simulator uses.

The simulated CAN actuator, the drop-test rig simulator and the discrepancy tool's models all
integrate this module; nothing else integrates actuator dynamics.

Bodies. The *motor* body is the rotor and gear train reflected to the output (J_r of Table 1).
It carries the drive torque (saturated at the torque limit), Coulomb and static friction and
viscous drag b_v. When the environment has inertia (an arm, a payload), a *load* body is joined
to the motor through the gearbox backlash: inside the dead band they move independently; at an
edge the motor engages the load with a perfectly inelastic impact and they move as one until
the contact torque would have to pull. With no load inertia the environment's torque acts on the
motor body directly (there is nothing for backlash to separate).

Friction (Karnopp). A body at rest stays at rest while the torque on it is within the static
friction tau_s; once moving it sees -tau_coul sign(w) - b_v w. A velocity that friction would
reverse within a step is set to zero, and the next step decides between sticking and breakaway.

Integration. Semi-implicit Euler with the viscous term implicit (stable for any b_v), substeps of
at most ``max_step_s`` (default 0.1 ms; ample for impedance gains up to the AK80's 500 N m/rad
on the smallest Table 1 inertia, where w dt ~ 0.1).

Sensing. The encoder sits on the motor: the reported position is the motor position quantised
to 2 pi / (counts_per_rev * reduction) at the output. Time is always passed in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from transparency_ros.core.config import ActuatorParams
from transparency_ros.core.errors import ModelError, shown

# drive torque [N m] as a function of (measured position [rad], velocity [rad/s])
DriveLaw = Callable[[float, float], float]


def zero_drive(_position: float, _velocity: float) -> float:
    return 0.0


@dataclass(frozen=True)
class PhysicsParams:
    rotor_inertia_kgm2: float
    static_friction_nm: float
    coulomb_friction_nm: float
    viscous_nms_per_rad: float
    backlash_rad: float
    torque_limit_nm: float
    encoder_counts_per_rev: int
    reduction: float
    # Position-dependent friction (gear/bearing eccentricity): b_v and tau_coul are scaled by
    # 1 + ripple * sin(cycles * theta_out). 0 (default) is Table 1's constant friction.
    friction_ripple: float = 0.0
    friction_ripple_cycles_per_rev: float = 1.0

    def __post_init__(self) -> None:
        checks = {
            "rotor_inertia_kgm2": self.rotor_inertia_kgm2 > 0,
            "static_friction_nm": self.static_friction_nm >= self.coulomb_friction_nm >= 0,
            "viscous_nms_per_rad": self.viscous_nms_per_rad >= 0,
            "backlash_rad": self.backlash_rad >= 0,
            "torque_limit_nm": self.torque_limit_nm > 0,
            "encoder_counts_per_rev": self.encoder_counts_per_rev > 0,
            "reduction": self.reduction > 0,
            "friction_ripple": 0.0 <= self.friction_ripple < 1.0,
            "friction_ripple_cycles_per_rev": self.friction_ripple_cycles_per_rev > 0,
        }
        for name, ok in checks.items():
            if not ok or not math.isfinite(float(getattr(self, name))):
                raise ModelError(f"PhysicsParams.{name} out of range: {getattr(self, name)!r}")

    @classmethod
    def from_actuator(
        cls,
        actuator: ActuatorParams,
        *,
        encoder_counts_per_rev: int = 16384,
        torque_limit_nm: float | None = None,
        friction_ripple: float = 0.0,
    ) -> PhysicsParams:
        """Table 1 values; the torque limit defaults to the actuator's peak torque."""
        return cls(
            rotor_inertia_kgm2=actuator.reflected_inertia_kgm2,
            static_friction_nm=actuator.static_friction_nm,
            coulomb_friction_nm=actuator.coulomb_friction_nm,
            viscous_nms_per_rad=actuator.viscous_damping_nms_per_rad,
            backlash_rad=actuator.backlash_rad,
            torque_limit_nm=actuator.peak_torque_nm if torque_limit_nm is None else torque_limit_nm,
            encoder_counts_per_rev=encoder_counts_per_rev,
            reduction=actuator.reduction_ratio,
            friction_ripple=friction_ripple,
        )

    @property
    def position_resolution_rad(self) -> float:
        return 2.0 * math.pi / (self.encoder_counts_per_rev * self.reduction)


class Environment(Protocol):
    """What the output shaft is attached to."""

    @property
    def inertia_kgm2(self) -> float:
        """Inertia of the load on the output [kg m^2]; 0 when nothing is attached."""
        ...

    def torque_nm(self, position_rad: float, velocity_rad_s: float, time_s: float) -> float:
        """External torque on the output (on the load body when it has inertia)."""
        ...


class FreeEnvironment:
    """Nothing attached: the output turns freely."""

    inertia_kgm2 = 0.0

    def torque_nm(self, position_rad: float, velocity_rad_s: float, time_s: float) -> float:
        return 0.0


@dataclass
class InertialLoad:
    """A rigid load with an optional external torque, e.g. an arm or a payload."""

    inertia_kgm2: float
    external_torque: Callable[[float, float, float], float] | None = None

    def torque_nm(self, position_rad: float, velocity_rad_s: float, time_s: float) -> float:
        if self.external_torque is None:
            return 0.0
        return self.external_torque(position_rad, velocity_rad_s, time_s)


@dataclass
class PhysicsState:
    time_s: float = 0.0
    motor_position_rad: float = 0.0
    motor_velocity_rad_s: float = 0.0
    load_position_rad: float = 0.0
    load_velocity_rad_s: float = 0.0
    engaged_side: int = 0  # -1: motor drives the load forward, +1: backward, 0: in the dead band
    applied_torque_nm: float = 0.0  # drive torque after saturation
    external_torque_nm: float = 0.0


class ActuatorPhysics:
    """Integrates one actuator (and its environment) forward in time."""

    def __init__(
        self,
        params: PhysicsParams,
        environment: Environment | None = None,
        *,
        max_step_s: float = 1e-4,
        initial_position_rad: float = 0.0,
    ) -> None:
        if not (math.isfinite(max_step_s) and max_step_s > 0):
            raise ModelError(f"max_step_s must be > 0, got {shown(max_step_s)}")
        self.params = params
        self.environment: Environment = environment or FreeEnvironment()
        self.max_step_s = max_step_s
        self.state = PhysicsState(
            motor_position_rad=initial_position_rad, load_position_rad=initial_position_rad
        )
        if self._has_load and params.backlash_rad == 0.0:
            self.state.engaged_side = -1

    @property
    def _has_load(self) -> bool:
        return self.environment.inertia_kgm2 > 0.0

    # ----------------------------------------------------------------- sensing

    @property
    def measured_position_rad(self) -> float:
        res = self.params.position_resolution_rad
        return round(self.state.motor_position_rad / res) * res

    @property
    def velocity_rad_s(self) -> float:
        return self.state.motor_velocity_rad_s

    @property
    def output_position_rad(self) -> float:
        """Where the output (load side) really is."""
        s = self.state
        return s.load_position_rad if self._has_load else s.motor_position_rad

    # ----------------------------------------------------------------- integration

    def advance(self, duration_s: float, drive: DriveLaw = zero_drive) -> None:
        """Integrate ``duration_s`` seconds with the drive law re-evaluated every substep."""
        if not math.isfinite(duration_s) or duration_s < 0:
            raise ModelError(f"duration must be finite and >= 0, got {duration_s!r}")
        steps = max(1, math.ceil(duration_s / self.max_step_s - 1e-9)) if duration_s > 0 else 0
        dt = duration_s / steps if steps else 0.0
        for _ in range(steps):
            self._substep(dt, drive)

    def _saturate(self, torque: float) -> float:
        limit = self.params.torque_limit_nm
        if not math.isfinite(torque):
            return 0.0
        return max(-limit, min(limit, torque))

    def _friction_scale(self) -> float:
        p = self.params
        if p.friction_ripple == 0.0:
            return 1.0
        angle = p.friction_ripple_cycles_per_rev * self.state.motor_position_rad
        return 1.0 + p.friction_ripple * math.sin(angle)

    def _friction_step(self, omega: float, inertia: float, torque_in: float, dt: float) -> float:
        """New velocity of a body with friction under the non-friction torque ``torque_in``."""
        p = self.params
        scale = self._friction_scale()
        coulomb, viscous = p.coulomb_friction_nm * scale, p.viscous_nms_per_rad * scale
        if omega == 0.0:
            if abs(torque_in) <= p.static_friction_nm * scale:
                return 0.0
            net = torque_in - math.copysign(coulomb, torque_in)
        else:
            net = torque_in - math.copysign(coulomb, omega)
        new = (omega + net / inertia * dt) / (1.0 + viscous * dt / inertia)
        if omega != 0.0 and new * omega < 0.0:
            return 0.0
        return new

    def _substep(self, dt: float, drive: DriveLaw) -> None:
        s, p = self.state, self.params
        tau = self._saturate(drive(self.measured_position_rad, s.motor_velocity_rad_s))
        s.applied_torque_nm = tau
        if not self._has_load:
            ext = self.environment.torque_nm(s.motor_position_rad, s.motor_velocity_rad_s, s.time_s)
            s.external_torque_nm = ext
            s.motor_velocity_rad_s = self._friction_step(
                s.motor_velocity_rad_s, p.rotor_inertia_kgm2, tau + ext, dt
            )
            s.motor_position_rad += s.motor_velocity_rad_s * dt
            s.load_position_rad, s.load_velocity_rad_s = (
                s.motor_position_rad,
                s.motor_velocity_rad_s,
            )
            s.time_s += dt
            return

        j_m, j_l = p.rotor_inertia_kgm2, self.environment.inertia_kgm2
        ext = self.environment.torque_nm(s.load_position_rad, s.load_velocity_rad_s, s.time_s)
        s.external_torque_nm = ext
        if s.engaged_side != 0:
            before = s.motor_velocity_rad_s
            omega = self._friction_step(before, j_m + j_l, tau + ext, dt)
            accel = (omega - before) / dt
            contact = j_l * accel - ext  # torque the motor exerts on the load
            keeps_contact = (
                p.backlash_rad == 0.0
                or (s.engaged_side < 0 and contact >= 0.0)
                or (s.engaged_side > 0 and contact <= 0.0)
            )
            if keeps_contact:
                s.motor_velocity_rad_s = s.load_velocity_rad_s = omega
                s.motor_position_rad += omega * dt
                s.load_position_rad = s.motor_position_rad + s.engaged_side * p.backlash_rad / 2
                s.time_s += dt
                return
            s.engaged_side = 0
        # separated: each body on its own, then look for an engagement at either edge
        s.motor_velocity_rad_s = self._friction_step(s.motor_velocity_rad_s, j_m, tau, dt)
        s.load_velocity_rad_s += ext / j_l * dt
        s.motor_position_rad += s.motor_velocity_rad_s * dt
        s.load_position_rad += s.load_velocity_rad_s * dt
        half = p.backlash_rad / 2
        gap = s.load_position_rad - s.motor_position_rad
        if abs(gap) >= half:
            side = -1 if gap < 0 else 1
            closing = (s.load_velocity_rad_s - s.motor_velocity_rad_s) * side
            s.load_position_rad = s.motor_position_rad + side * half
            if closing >= 0.0:  # inelastic engagement: common velocity, momentum conserved
                common = (j_m * s.motor_velocity_rad_s + j_l * s.load_velocity_rad_s) / (j_m + j_l)
                s.motor_velocity_rad_s = s.load_velocity_rad_s = common
                s.engaged_side = side
        s.time_s += dt


@dataclass(frozen=True)
class ImpedanceLaw:
    """tau = kp (p_d - p) + kd (v_d - v) + tau_ff: what MIT-mode and moteus firmware run."""

    kp: float
    kd: float
    position_rad: float
    velocity_rad_s: float
    torque_ff_nm: float

    def __call__(self, position: float, velocity: float) -> float:
        return (
            self.kp * (self.position_rad - position)
            + self.kd * (self.velocity_rad_s - velocity)
            + self.torque_ff_nm
        )


@dataclass(frozen=True)
class ConstantTorque:
    torque_nm: float

    def __call__(self, position: float, velocity: float) -> float:
        return self.torque_nm
