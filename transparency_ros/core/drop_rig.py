"""The drop-test rig of Sec. 3.1 as an environment of the one actuator physics.

A shuttle of mass m_s slides down a vertical rail onto the tip of the arm (length r) fixed to the
actuator output. More physics than eq. (2), because a real rig has it:
* gravity acts on the shuttle all the time (before, during and after contact), and the rail may
  brake it (Coulomb friction ``rail_friction_n``; 0 by default);
* the contact is compliant (a stiff spring-damper, ``contact_stiffness_n_per_m`` and a damping
  that gives ``restitution`` against an immovable arm), so the load-cell force exists and the
  shuttle can bounce;
* the actuator side (reflected inertia, static and Coulomb friction, viscous drag, backlash,
  encoder resolution) is :class:`~transparency_ros.core.actuator_physics.ActuatorPhysics`.

Geometry: the arm is horizontal at theta = 0; the shuttle's contact face is ``height`` above the
arm tip's rest position (where the arm rests at the release, which friction may leave away from
theta = 0); the tip's height is r sin(theta), so a strike turns the arm to negative theta. The
rig samples its sensors on a fixed 10 kHz grid, like the paper's DAQ: the load cell
(contact force, N) and the potentiometer (height of the contact face, m), each with Gaussian
noise of the given standard deviation (seeded: a trial is reproducible).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from transparency_ros.core.contact_model import restitution_damping_ratio
from transparency_ros.core.errors import ModelError, shown

GRAVITY = 9.81


@dataclass(frozen=True)
class RigParams:
    shuttle_mass_kg: float
    arm_length_m: float = 0.1
    arm_inertia_kgm2: float = 6.5e-5
    contact_stiffness_n_per_m: float = 2.0e5
    restitution: float = 0.3
    rail_friction_n: float = 0.0
    daq_rate_hz: float = 10_000.0
    force_noise_n: float = 0.05
    height_noise_m: float = 2e-5
    seed: int = 0

    def __post_init__(self) -> None:
        positive = {
            "shuttle_mass_kg": self.shuttle_mass_kg,
            "arm_length_m": self.arm_length_m,
            "contact_stiffness_n_per_m": self.contact_stiffness_n_per_m,
            "daq_rate_hz": self.daq_rate_hz,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise ModelError(f"rig {name} must be > 0, got {shown(value)}")
        non_negative = {
            "arm_inertia_kgm2": self.arm_inertia_kgm2,
            "rail_friction_n": self.rail_friction_n,
            "force_noise_n": self.force_noise_n,
            "height_noise_m": self.height_noise_m,
        }
        for name, value in non_negative.items():
            if not (math.isfinite(value) and value >= 0):
                raise ModelError(f"rig {name} must be >= 0, got {shown(value)}")
        if not 0.0 < self.restitution <= 1.0:
            raise ModelError(f"rig restitution must be in (0, 1], got {self.restitution!r}")

    @property
    def contact_damping_ns_per_m(self) -> float:
        """Damping of a spring-damper contact with this restitution against a fixed wall."""
        zeta = float(restitution_damping_ratio(self.restitution))
        return 2.0 * zeta * math.sqrt(self.contact_stiffness_n_per_m * self.shuttle_mass_kg)


@dataclass
class ShuttleState:
    released: bool = False
    height_m: float = 0.0  # contact face above the arm tip's rest position
    tip_rest_m: float = 0.0  # the tip's height r sin(theta) where the arm rested at the release
    velocity_m_s: float = 0.0  # positive up
    force_n: float = 0.0  # contact force on the shuttle (load cell), positive pushing up
    release_s: float | None = None
    first_contact_s: float | None = None
    contacts: int = 0
    in_contact: bool = False


@dataclass(frozen=True)
class DaqSample:
    time_s: float  # physics time
    force_n: float  # load cell, with noise
    height_m: float  # potentiometer, with noise


@dataclass
class DropRig:
    """Environment for :class:`ActuatorPhysics`: the arm's inertia plus the shuttle contact."""

    params: RigParams
    state: ShuttleState = field(default_factory=ShuttleState)
    daq: list[DaqSample] = field(default_factory=list)
    _last_time_s: float | None = None
    _next_sample_s: float | None = None
    _rng: random.Random = field(init=False)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.params.seed)

    @property
    def inertia_kgm2(self) -> float:
        return self.params.arm_inertia_kgm2

    def hold(self, height_m: float) -> None:
        """Lift the shuttle off the arm and hold it with its face ``height_m`` above the tip."""
        if not (math.isfinite(height_m) and height_m > 0):
            raise ModelError(f"drop height must be > 0 m, got {shown(height_m)}")
        self.state = ShuttleState(False, height_m)
        self.daq.clear()
        self._next_sample_s = None

    def release(self, height_m: float | None = None) -> None:
        """Let the shuttle go (from ``height_m`` if given, else from where it is held)."""
        if height_m is not None or self.state.released:
            self.hold(self.state.height_m if height_m is None else height_m)
        self.state.released = True
        self.state.release_s = None  # set at the next integration step

    def take_daq(self) -> list[DaqSample]:
        """The DAQ samples recorded since the last call."""
        samples, self.daq = self.daq, []
        return samples

    def torque_nm(self, position_rad: float, velocity_rad_s: float, time_s: float) -> float:
        p, s = self.params, self.state
        dt = 0.0 if self._last_time_s is None else max(0.0, time_s - self._last_time_s)
        self._last_time_s = time_s
        if not s.released:
            self._sample(time_s)  # the DAQ runs while the shuttle is held too
            return 0.0
        r = p.arm_length_m
        if s.release_s is None:
            s.release_s = time_s
            s.tip_rest_m = r * math.sin(position_rad)
        # heights are above the tip at rest (the bag contract), wherever friction stopped the arm
        tip_height = r * math.sin(position_rad) - s.tip_rest_m
        tip_speed = r * math.cos(position_rad) * velocity_rad_s
        penetration = tip_height - s.height_m
        force = 0.0
        if penetration > 0.0:
            force = max(
                0.0,
                p.contact_stiffness_n_per_m * penetration
                + p.contact_damping_ns_per_m * (tip_speed - s.velocity_m_s),
            )
        if force > 0.0 and not s.in_contact:
            s.contacts += 1
            if s.first_contact_s is None:
                s.first_contact_s = time_s
        s.in_contact = force > 0.0
        s.force_n = force
        if dt > 0.0:  # trapezoidal (exact in free fall); rail friction cannot reverse the motion
            v = s.velocity_m_s + (force / p.shuttle_mass_kg - GRAVITY) * dt
            if p.rail_friction_n > 0.0 and v != 0.0:
                slowed = v - math.copysign(p.rail_friction_n / p.shuttle_mass_kg * dt, v)
                v = slowed if slowed * v > 0.0 else 0.0
            s.height_m += 0.5 * (s.velocity_m_s + v) * dt
            s.velocity_m_s = v
        self._sample(time_s)
        return -force * r * math.cos(position_rad)

    def _sample(self, time_s: float) -> None:
        p, s = self.params, self.state
        period = 1.0 / p.daq_rate_hz
        if self._next_sample_s is None:
            self._next_sample_s = time_s
        while self._next_sample_s <= time_s + 1e-12:
            back = time_s - self._next_sample_s  # the grid instant is up to one step earlier
            self.daq.append(
                DaqSample(
                    self._next_sample_s,
                    s.force_n + self._rng.gauss(0.0, p.force_noise_n),
                    s.height_m - s.velocity_m_s * back + self._rng.gauss(0.0, p.height_noise_m),
                )
            )
            self._next_sample_s += period
