"""The one actuator physics: friction, stiction, drag, torque limit, encoder, backlash."""

from __future__ import annotations

import math

import pytest

from transparency_ros.core.actuator_physics import (
    ActuatorPhysics,
    ConstantTorque,
    ImpedanceLaw,
    InertialLoad,
    PhysicsParams,
)
from transparency_ros.core.config import get_actuator
from transparency_ros.core.errors import ModelError


def params(name: str = "U10DD", **overrides: float) -> PhysicsParams:
    base = PhysicsParams.from_actuator(get_actuator(name))
    return PhysicsParams(**{**base.__dict__, **overrides})


def test_coasting_matches_the_analytic_solution() -> None:
    """J w' = -b w - tau_c: w(t) = (w0 + tau_c/b) e^{-b t/J} - tau_c/b until it stops."""
    p = params("EC60")
    physics = ActuatorPhysics(p, max_step_s=1e-6)
    physics.state.motor_velocity_rad_s = 20.0
    j, b, tc = p.rotor_inertia_kgm2, p.viscous_nms_per_rad, p.coulomb_friction_nm
    t = 0.01
    physics.advance(t)
    expected = (20.0 + tc / b) * math.exp(-b * t / j) - tc / b
    assert physics.velocity_rad_s == pytest.approx(expected, rel=1e-4)
    t_stop = j / b * math.log((20.0 + tc / b) / (tc / b))
    physics.advance(t_stop)  # well past the stop
    assert physics.velocity_rad_s == 0.0


def test_stiction_holds_below_and_breaks_away_above_static_friction() -> None:
    p = params("T2822")
    held = ActuatorPhysics(p)
    held.advance(0.2, ConstantTorque(0.99 * p.static_friction_nm))
    assert held.state.motor_position_rad == 0.0 and held.velocity_rad_s == 0.0
    moving = ActuatorPhysics(p)
    moving.advance(0.2, ConstantTorque(1.01 * p.static_friction_nm))
    assert moving.velocity_rad_s > 0.0 and moving.state.motor_position_rad > 0.0


def test_torque_limit_saturates_the_drive() -> None:
    p = params("U10DD", torque_limit_nm=1.0)
    physics = ActuatorPhysics(p)
    physics.advance(1e-3, ConstantTorque(100.0))
    assert physics.state.applied_torque_nm == 1.0
    physics.advance(1e-3, ConstantTorque(math.nan))
    assert physics.state.applied_torque_nm == 0.0


def test_encoder_quantises_the_motor_position() -> None:
    p = params("T2822", encoder_counts_per_rev=4096)
    physics = ActuatorPhysics(p, initial_position_rad=0.123456)
    step = 2 * math.pi / (4096 * 17576 / 343)
    assert p.position_resolution_rad == pytest.approx(step)
    measured = physics.measured_position_rad
    assert abs(measured - 0.123456) <= step / 2
    assert measured / step == pytest.approx(round(measured / step), abs=1e-9)


def test_impedance_settles_within_the_static_friction_band() -> None:
    p = params("U10DD")
    physics = ActuatorPhysics(p)
    physics.advance(
        1.0, ImpedanceLaw(kp=2.0, kd=0.0, position_rad=0.5, velocity_rad_s=0.0, torque_ff_nm=0.0)
    )
    error = 0.5 - physics.state.motor_position_rad
    assert physics.velocity_rad_s == 0.0
    assert abs(error) <= p.static_friction_nm / 2.0 + 1e-9


def test_backlash_dead_band_and_inelastic_engagement() -> None:
    p = params("EC60", static_friction_nm=0.0, coulomb_friction_nm=0.0, viscous_nms_per_rad=0.0)
    load = InertialLoad(inertia_kgm2=p.rotor_inertia_kgm2)  # equal inertias
    physics = ActuatorPhysics(p, load, max_step_s=1e-6)
    half = p.backlash_rad / 2
    # the motor turns through the dead band before the load moves
    physics.state.motor_velocity_rad_s = 1.0
    physics.advance(0.9 * half / 1.0)
    assert physics.state.load_velocity_rad_s == 0.0 and physics.state.engaged_side == 0
    physics.advance(0.2 * half / 1.0)
    s = physics.state
    assert s.engaged_side == -1
    # perfectly inelastic, equal inertias: half the speed each, momentum conserved
    assert s.motor_velocity_rad_s == pytest.approx(0.5) and s.load_velocity_rad_s == pytest.approx(
        0.5
    )
    assert s.load_position_rad - s.motor_position_rad == pytest.approx(-half)
    # reversing the drive separates the bodies again
    physics.advance(1e-3, ConstantTorque(-0.5))
    assert physics.state.engaged_side == 0
    assert physics.state.motor_velocity_rad_s < physics.state.load_velocity_rad_s


def test_load_torque_passes_through_engaged_gears() -> None:
    p = params("U10GB", backlash_rad=0.0)
    load = InertialLoad(0.01, external_torque=lambda _p, _v, _t: -1.0)
    physics = ActuatorPhysics(p, load)
    physics.advance(0.1)  # 1 N m > static friction: the load back-drives the motor
    assert physics.state.motor_velocity_rad_s < 0.0
    assert physics.state.load_position_rad == physics.state.motor_position_rad


def test_bad_inputs() -> None:
    with pytest.raises(ModelError, match="static_friction_nm"):
        params("U10DD", static_friction_nm=0.01)
    with pytest.raises(ModelError, match="duration"):
        ActuatorPhysics(params()).advance(-1.0)
    with pytest.raises(ModelError, match="max_step_s"):
        ActuatorPhysics(params(), max_step_s=0.0)
