"""What ``actuator_driver`` talks to, made from its parameters: the wire protocol and, for
``simulate``, the simulated device of the same protocol and what its output drives."""

from __future__ import annotations

from typing import Any

from transparency_ros.canbus import mit
from transparency_ros.canbus.client import BusSettings
from transparency_ros.canbus.errors import BusError
from transparency_ros.canbus.protocol import (
    ActuatorProtocol,
    MitProtocol,
    MoteusProtocol,
    ODriveProtocol,
)
from transparency_ros.canbus.sim_device import (
    MitDevice,
    MoteusDevice,
    ODriveDevice,
    Personality,
    SimulatedActuator,
)
from transparency_ros.core.actuator_physics import ActuatorPhysics, Environment, PhysicsParams
from transparency_ros.core.ball_on_rail import BallOnRail
from transparency_ros.core.config import get_actuator, load_drop_test
from transparency_ros.core.drop_rig import DropRig, RigParams
from transparency_ros.core.feel_cage_config import load_setup


def make_protocol(v: dict[str, Any]) -> tuple[ActuatorProtocol, Personality]:
    """The host-side protocol and the matching simulated device for the parameters."""
    g = v["gear_ratio"]
    if v["protocol"] == "mit":
        limits = mit.MitLimits(*(v[f"mit.{k}"] for k in (
            "p_min_rad", "p_max_rad", "v_min_rad_s", "v_max_rad_s", "kp_min", "kp_max",
            "kd_min", "kd_max", "t_min_nm", "t_max_nm")))  # fmt: skip
        return (
            MitProtocol(v["motor_id"], limits, gear_ratio=g),
            MitDevice(v["motor_id"], limits, gear_ratio=g),
        )
    if v["protocol"] == "odrive":
        return ODriveProtocol(v["motor_id"], gear_ratio=g), ODriveDevice(
            v["motor_id"], gear_ratio=g
        )
    kp, kd = v["moteus.kp_nm_per_rev"], v["moteus.kd_nms_per_rev"]
    return (
        MoteusProtocol(
            v["motor_id"],
            kp_nm_per_rev=kp,
            kd_nms_per_rev=kd,
            watchdog_timeout_s=v["moteus.watchdog_timeout_s"],
            gear_ratio=g,
        ),
        MoteusDevice(v["motor_id"], kp_nm_per_rev=kp, kd_nms_per_rev=kd, gear_ratio=g),
    )


def make_environment(v: dict[str, Any]) -> Environment | None:
    """What the simulated output drives (``sim_environment``); None: nothing (free)."""
    if v["sim_environment"] == "drop_rig":
        drop = load_drop_test()
        mass = v["sim_shuttle_mass_kg"] or drop.shuttle_mass_for(v["sim_actuator"])
        return DropRig(
            RigParams(
                shuttle_mass_kg=mass,
                arm_length_m=drop.arm_length_m,
                arm_inertia_kgm2=drop.arm_inertia_kgm2,
                seed=v["sim_rig_seed"],
            )
        )
    if v["sim_environment"] != "ball_on_rail":
        return None
    setup = load_setup()
    return BallOnRail(setup.balls[v["sim_ball"]], setup.geometry, placed=v["sim_place_ball"])


def start_simulation(
    v: dict[str, Any], personality: Personality, settings: BusSettings
) -> SimulatedActuator:
    """The simulated actuator on the (virtual) bus, running."""
    if v["interface"] != "virtual":
        raise BusError(
            "simulate:=true needs interface:=virtual (a real bus has a "
            "real motor); set simulate:=false for hardware"
        )
    actuator = get_actuator(v["sim_actuator"])
    physics = ActuatorPhysics(
        PhysicsParams.from_actuator(
            actuator,
            encoder_counts_per_rev=v["sim_encoder_counts_per_rev"],
            friction_ripple=v["sim_friction_ripple"],
        ),
        make_environment(v),
    )
    return SimulatedActuator(physics, personality, settings).start()
