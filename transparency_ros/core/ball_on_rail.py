"""Ball-on-rail environment for the feel-cage task (Sec. 4.1), attached to the actuator output.

Geometry (one for every actuator and ball; values in ``config/feel_cage.yaml``):

* The arm (length ``arm_length_m`` from the axis to its striking face) turns in a plane above a
  straight horizontal rail. The rail is tangent to the circle of the arm's tip at the *contact
  angle* theta_c, so near theta_c the tip moves along the rail: x_tip = r sin(theta - theta_c)
  (x along the rail, 0 where the tip touches the resting ball's surface; the tip is off the rail
  beyond +-90 degrees).
* The ball rests on the rail in front of the tip. A strike pushes it in +x, towards the end of
  the workspace at ``exit_m``: a ball whose centre passes it is lost.
* The cage: a gate bar on the arm's hub closes the rail at ``exit_m`` when the arm has turned
  back (clockwise) to the cage angle theta_c - ``cage_angle_rad``. The ball is caged if the gate
  closes while the ball is still inside the workspace.

Contact: a compliant spring-damper between tip and ball (stiffness per ball; damping set so that
a ball bouncing off an immovable arm leaves with its coefficient of restitution e), acting only
in compression. The ball rolls without slipping (effective mass 7/5 m for a solid sphere) against
rolling resistance C_rr m g. The contact force on the ball is F; on the arm it is a torque
-F r cos(theta - theta_c) about the axis.

The environment integrates the ball itself: the physics calls :meth:`torque_nm` once per
substep with the arm's state and the time, which is the only clock it uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from transparency_ros.core.contact_model import restitution_damping_ratio
from transparency_ros.core.errors import ModelError

GRAVITY = 9.81
ROLLING_MASS_FACTOR = 7.0 / 5.0  # solid sphere rolling without slipping


@dataclass(frozen=True)
class Ball:
    name: str
    mass_kg: float
    diameter_m: float
    restitution: float  # against the aluminium arm
    rolling_resistance: float  # C_rr, dimensionless
    contact_stiffness_n_per_m: float

    def __post_init__(self) -> None:
        if not (self.mass_kg > 0 and self.diameter_m > 0 and self.contact_stiffness_n_per_m > 0):
            raise ModelError(f"ball {self.name}: mass, diameter and stiffness must be > 0")
        if not 0.0 < self.restitution <= 1.0:
            raise ModelError(f"ball {self.name}: restitution must be in (0, 1]")
        if not 0.0 <= self.rolling_resistance < 1.0:
            raise ModelError(f"ball {self.name}: rolling resistance must be in [0, 1)")

    @property
    def radius_m(self) -> float:
        return self.diameter_m / 2.0

    @property
    def damping_ratio(self) -> float:
        """Contact damping ratio giving restitution e against an immovable arm."""
        return float(restitution_damping_ratio(self.restitution))

    @property
    def contact_damping_ns_per_m(self) -> float:
        m = self.mass_kg * ROLLING_MASS_FACTOR
        return 2.0 * self.damping_ratio * math.sqrt(self.contact_stiffness_n_per_m * m)


@dataclass(frozen=True)
class RailGeometry:
    arm_length_m: float  # axis to the striking face
    arm_inertia_kgm2: float
    contact_angle_rad: float  # theta_c, where the rail is tangent to the tip's circle
    exit_m: float  # end of the workspace along the rail, from the resting contact point
    cage_angle_rad: float  # clockwise turn from theta_c that brings the gate down

    def __post_init__(self) -> None:
        if not (
            self.arm_length_m > 0
            and self.arm_inertia_kgm2 >= 0
            and self.exit_m > 0
            and self.cage_angle_rad > 0
        ):
            raise ModelError("rail geometry: lengths and angles must be > 0")
        if self.exit_m >= self.arm_length_m:
            raise ModelError("rail geometry: the exit must lie within the arm's reach")

    @property
    def cage_position_rad(self) -> float:
        return self.contact_angle_rad - self.cage_angle_rad


def wrap_angle(phi: float) -> float:
    """Angle into [-pi, pi): the arm passes the rail once per revolution."""
    return (phi + math.pi) % (2.0 * math.pi) - math.pi


@dataclass
class BallState:
    x_m: float = 0.0  # ball centre along the rail, 0 = resting position
    v_m_s: float = 0.0
    in_contact: bool = False
    contacts: int = 0  # separate strikes so far
    first_contact_s: float | None = None
    max_force_n: float = 0.0
    peak_speed_m_s: float = 0.0
    exit_s: float | None = None  # when the centre first passed the workspace exit


@dataclass
class BallOnRail:
    """The environment the physics integrates: arm inertia plus the ball contact torque."""

    ball: Ball
    geometry: RailGeometry
    state: BallState = field(default_factory=BallState)
    placed: bool = True  # False: no ball on the rail yet (see place())
    _last_time_s: float | None = None

    @property
    def inertia_kgm2(self) -> float:
        return self.geometry.arm_inertia_kgm2

    def place(self, theta_rad: float) -> bool:
        """Put the ball on the rail now, if the arm is clear of it; True when placed."""
        if self.placed:
            return True
        if self.tip_x(theta_rad) is not None:
            return False
        self.state = BallState()
        self.placed = True
        return True

    def tip_x(self, theta_rad: float) -> float | None:
        """Tip position along the rail, or None when the tip is off the rail."""
        phi = wrap_angle(theta_rad - self.geometry.contact_angle_rad)
        if abs(phi) >= math.pi / 2:
            return None
        return self.geometry.arm_length_m * math.sin(phi)

    def torque_nm(self, position_rad: float, velocity_rad_s: float, time_s: float) -> float:
        g, b, s = self.geometry, self.ball, self.state
        dt = 0.0 if self._last_time_s is None else max(0.0, time_s - self._last_time_s)
        self._last_time_s = time_s
        if not self.placed:
            return 0.0
        phi = wrap_angle(position_rad - g.contact_angle_rad)
        force = 0.0
        x_tip = self.tip_x(position_rad)
        if x_tip is not None:
            penetration = x_tip - s.x_m
            if penetration > 0.0:
                tip_speed = g.arm_length_m * math.cos(phi) * velocity_rad_s
                force = max(
                    0.0,
                    b.contact_stiffness_n_per_m * penetration
                    + b.contact_damping_ns_per_m * (tip_speed - s.v_m_s),
                )
        if force > 0.0 and not s.in_contact:
            s.contacts += 1
            if s.first_contact_s is None:
                s.first_contact_s = time_s
        s.in_contact = force > 0.0
        s.max_force_n = max(s.max_force_n, force)
        # ball: semi-implicit Euler with rolling resistance that cannot reverse the motion
        if dt > 0.0:
            m = b.mass_kg * ROLLING_MASS_FACTOR
            resist = b.rolling_resistance * b.mass_kg * GRAVITY
            v = s.v_m_s + force / m * dt
            if v != 0.0:
                slowed = v - math.copysign(resist / m * dt, v)
                v = slowed if slowed * v > 0.0 else 0.0
            s.v_m_s = v
            s.x_m += v * dt
            s.peak_speed_m_s = max(s.peak_speed_m_s, abs(v))
            if s.exit_s is None and s.x_m > g.exit_m:
                s.exit_s = time_s
        if force == 0.0:
            return 0.0
        return -force * g.arm_length_m * math.cos(phi)

    @property
    def lost(self) -> bool:
        return self.placed and self.state.x_m > self.geometry.exit_m
