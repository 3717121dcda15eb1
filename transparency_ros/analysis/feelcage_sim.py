"""The feel-cage task (Table 2) simulated from the project's cores, without ROS.

Same pieces the nodes use: the actuator physics with the ball-on-rail environment (the simulated
actuator), eq. (1) and the Schmitt detector (the estimator), the feel -> process -> act transition
function (the behavior), sampled at the driver's 1 kHz. Used to study Table 2 quickly and as the
reference the real-node run is compared with.

Procedure per cell, as in the paper:
1. e_s: sweep at 1 rev/s without a ball until steady; e_s is the largest |theta_d - theta_a| over
   the last revolution (the paper's "largest steady-state error").
2. trial: from that steady sweep, shortly before the contact angle, with the ball at rest on the
   rail; contact is detected when the error exceeds e_s + epsilon (k_s epsilon = 0.02 N m);
   after t_process the arm is driven CW open loop at 10.5 V to the cage angle.
3. the trial ends caged, lost (the ball passed the workspace exit first) or with no detection.
   t_budget is the time from contact until the ball would have left the workspace.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from transparency_ros.core import feel_cage as fc
from transparency_ros.core.actuator_physics import (
    ActuatorPhysics,
    InertialLoad,
    PhysicsParams,
    PhysicsState,
)
from transparency_ros.core.ball_on_rail import BallOnRail
from transparency_ros.core.config import ActuatorParams, get_actuator
from transparency_ros.core.estimator import DetectorSettings, SchmittDetector
from transparency_ros.core.feel_cage_config import FeelCageSetup, load_setup

ACTUATORS = ("U10DD", "EC60", "T2822", "U10GB")
__all__ = [
    "ACTUATORS",
    "PAPER_TABLE2",
    "FeelCageSetup",
    "load_setup",
    "simulate_cell",
    "steady_sweep",
    "table2",
    "time_to_cage",
]


@dataclass(frozen=True)
class SteadySweep:
    state: PhysicsState  # at the end of the settle time
    theta_d_rad: float
    steady_error_rad: float  # e_s


def _impedance(k_s: float, theta_d: float) -> Any:
    return lambda position, _velocity: k_s * (theta_d - position)


def steady_sweep(actuator: ActuatorParams, setup: FeelCageSetup) -> SteadySweep:
    """Sweep at 1 rev/s with only the arm attached; e_s over the last revolution."""
    params = PhysicsParams.from_actuator(actuator, friction_ripple=setup.friction_ripple)
    physics = ActuatorPhysics(params, InertialLoad(setup.geometry.arm_inertia_kgm2))
    dt = 1.0 / setup.sample_rate_hz
    speed = 2.0 * math.pi
    errors: list[float] = []
    t = 0.0
    steps = round(setup.settle_s / dt)
    for i in range(steps):
        theta_d = speed * t
        physics.advance(dt, _impedance(setup.k_s_nm_per_rad, theta_d))
        t += dt
        if i >= steps - round(1.0 / dt):
            errors.append(speed * t - physics.measured_position_rad)
    return SteadySweep(physics.state, speed * t, max(abs(e) for e in errors))


def _resume(physics: ActuatorPhysics, sweep: SteadySweep, output_angle_rad: float) -> float:
    """Start ``physics`` in the steady sweep's state, turned so the output is at the given
    angle; return the rotation applied (add it to the sweep's theta_d)."""
    shift = output_angle_rad - sweep.state.load_position_rad
    s, steady = physics.state, sweep.state
    s.motor_position_rad = steady.motor_position_rad + shift
    s.load_position_rad = steady.load_position_rad + shift
    s.motor_velocity_rad_s = steady.motor_velocity_rad_s
    s.load_velocity_rad_s = steady.load_velocity_rad_s
    s.engaged_side = steady.engaged_side
    return shift


def simulate_cell(actuator_name: str, ball_name: str, setup: FeelCageSetup,
                  sweep: SteadySweep | None = None) -> fc.TrialRecord:  # fmt: skip
    actuator = get_actuator(actuator_name)
    sweep = sweep or steady_sweep(actuator, setup)
    geometry = setup.geometry
    env = BallOnRail(setup.balls[ball_name], geometry)
    physics = ActuatorPhysics(
        PhysicsParams.from_actuator(actuator, friction_ripple=setup.friction_ripple), env
    )
    # continue the steady sweep, shifted so the arm is just before the contact angle
    shift = _resume(physics, sweep, geometry.contact_angle_rad - setup.start_before_contact_rad)
    theta_d0 = sweep.theta_d_rad + shift

    detector = SchmittDetector(
        DetectorSettings(
            contact_onset=sweep.steady_error_rad + setup.epsilon_rad,
            contact_release=sweep.steady_error_rad + setup.epsilon_rad / 2,
        )
    )
    config = fc.FeelCageConfig(
        act_torque_nm=fc.open_loop_torque_nm(actuator, -setup.act_voltage_v),
        cage_position_rad=geometry.cage_position_rad,
        process_time_s=setup.process_time_s,
    )
    dt_ns = round(1e9 / setup.sample_rate_hz)
    dt = dt_ns * 1e-9
    t_ns, t = 0, 0.0  # the sample clock in integer nanoseconds, as stamps are
    state = fc.BehaviorState(fc.Phase.SWEEP, 0.0, theta_d0)
    command: fc.Command | None = fc.Sweep(theta_d0, config.sweep_speed_rad_s)
    lost_s: float | None = None
    end_s: float | None = None
    horizon = 3.0
    while t < horizon:
        law = _law(command, setup.k_s_nm_per_rad)
        physics.advance(dt, law)
        t_ns += dt_ns
        t = t_ns * 1e-9
        if lost_s is None and env.lost:
            lost_s = t
        if state.phase in (fc.Phase.CAGED, fc.Phase.LOST):
            if end_s is None:
                end_s = t
            if lost_s is not None or t - end_s > setup.after_cage_s:
                break
            continue
        position = physics.measured_position_rad
        if state.phase is fc.Phase.SWEEP and isinstance(command, fc.Sweep):
            error = command.position_rad - position
            for event in detector.update("arm", t_ns, error, setup.k_s_nm_per_rad * error):
                state = fc.on_contact(state, event.stamp_ns * 1e-9)
        # the ball counts as lost once it passed the exit before the gate closed
        state, command = fc.step(
            state, config, t, position, ball_lost=env.lost and state.phase is not fc.Phase.CAGED
        )
    return fc.record(state, env.state.first_contact_s, lost_s)


def _law(command: fc.Command | None, k_s: float) -> Any:
    if isinstance(command, fc.Sweep):
        return _impedance(k_s, command.position_rad)
    if isinstance(command, fc.Torque):
        torque = command.torque_nm
        return lambda _p, _v: torque
    if isinstance(command, fc.Hold):
        return _impedance(k_s, command.position_rad)
    return lambda _p, _v: 0.0


def time_to_cage(actuator_name: str, setup: FeelCageSetup,
                 sweep: SteadySweep | None = None) -> float:  # fmt: skip
    """How long the act phase takes from the contact angle, sweeping at 1 rev/s, with no ball:
    the t_act an actuator needs, also where it never got to act."""
    actuator = get_actuator(actuator_name)
    sweep = sweep or steady_sweep(actuator, setup)
    params = PhysicsParams.from_actuator(actuator, friction_ripple=setup.friction_ripple)
    physics = ActuatorPhysics(params, InertialLoad(setup.geometry.arm_inertia_kgm2))
    _resume(physics, sweep, setup.geometry.contact_angle_rad)
    torque = fc.open_loop_torque_nm(actuator, -setup.act_voltage_v)
    dt, t = 1.0 / setup.sample_rate_hz, 0.0
    while physics.measured_position_rad > setup.geometry.cage_position_rad and t < 5.0:
        physics.advance(dt, lambda _p, _v: torque)
        t += dt
    return t


def table2(setup: FeelCageSetup) -> dict[tuple[str, str], fc.TrialRecord]:
    results: dict[tuple[str, str], fc.TrialRecord] = {}
    for name in ACTUATORS:
        sweep = steady_sweep(get_actuator(name), setup)
        for ball in setup.balls:
            results[(ball, name)] = simulate_cell(name, ball, setup, sweep)
    return results


PAPER_TABLE2 = {
    "rubber": ("feel + cage", "feel", "no detection", "no detection"),
    "lacrosse": ("feel + cage", "feel", "no detection", "no detection"),
    "bocce": ("feel + cage", "feel + cage", "feel", "no detection"),
}
