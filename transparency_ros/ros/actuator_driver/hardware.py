"""What ``actuator_driver`` talks to, made from its parameters: the wire protocol and, for
``simulate``, the simulated device of the same protocol and what its output drives."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from transparency_ros.canbus import mit
from transparency_ros.canbus.client import BusSettings
from transparency_ros.canbus.errors import BusError
from transparency_ros.canbus.protocol import (
    PROTOCOLS,
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
from transparency_ros.canbus.sim_robot import SimulatedBus, SimulatedBuses
from transparency_ros.core.actuator_physics import ActuatorPhysics, Environment, PhysicsParams
from transparency_ros.core.ball_on_rail import BallOnRail
from transparency_ros.core.config import get_actuator, load_drop_test
from transparency_ros.core.driver import DriverSettings
from transparency_ros.core.drop_rig import DropRig, RigParams
from transparency_ros.core.feel_cage_config import load_setup


@dataclass(frozen=True)
class MotorSpec:
    """One motor of a multi-motor driver: id, joint name and bus channel."""

    motor_id: int
    joint: str
    channel: str


def motor_specs(v: dict[str, Any]) -> list[MotorSpec]:
    """The motors of ``motor_ids``/``joint_names``/``channels``; [] for the single-motor
    driver (``motor_ids`` [-1]). Raises ValueError naming the parameter that is wrong."""
    ids = list(v["motor_ids"])
    if ids == [-1]:
        return []
    if not ids or any(not 0 <= i <= 0x7FF for i in ids):
        raise ValueError(f"motor_ids must be ids in [0, 2047] (or [-1]), got {ids}")
    if len(set(ids)) != len(ids):
        raise ValueError(f"motor_ids has duplicates: {ids}")
    names = list(v["joint_names"])
    names = [f"joint_{i}" for i in ids] if names == [""] else names
    reserved = [n for n in names if "." in n or n in ("mit", "moteus")]
    if reserved:
        raise ValueError(
            f"joint_names {reserved}: a joint name is a parameter prefix (knee.k_s) and may "
            "not contain '.' or be 'mit' or 'moteus'"
        )
    if len(names) != len(ids) or any(not n for n in names) or len(set(names)) != len(names):
        raise ValueError(
            f"joint_names must be {len(ids)} distinct non-empty names (one per motor_ids "
            f"entry), got {list(v['joint_names'])}"
        )
    channels = list(v["channels"])
    channels = [v["channel"]] * len(ids) if channels == [""] else channels
    if len(channels) != len(ids) or any(not c for c in channels):
        raise ValueError(
            f"channels must have one channel per motor_ids entry ({len(ids)}), got "
            f"{list(v['channels'])}"
        )
    return [MotorSpec(i, n, c) for i, n, c in zip(ids, names, channels, strict=True)]


# A robot's simulated motors integrate at 0.25 ms (a lone actuator at 0.1 ms): twelve at 0.1 ms
# took half of the interpreter at 1 kHz and starved the driver's loop. Semi-implicit Euler stays
# stable for k_d < 2 J / step (U10DD: 3.6 N m s/rad) and k_s < J (2 / step)^2 (28,000 N m/rad).
ROBOT_SIM_STEP_S = 2.5e-4


def start_simulated_buses(
    v: dict[str, Any], specs: list[MotorSpec], personalities: list[Personality], fd: bool
) -> SimulatedBuses:
    """One simulated bus per channel with the motors on it, all served by one thread (free
    joints: a robot's simulated motors drive nothing but themselves)."""
    if v["interface"] != "virtual":
        raise BusError("simulate:=true needs interface:=virtual")
    if v["sim_environment"] != "free":
        raise BusError("with motor_ids the simulated motors are free (sim_environment:=free)")
    actuator = get_actuator(v["sim_actuator"])
    params = PhysicsParams.from_actuator(
        actuator,
        encoder_counts_per_rev=v["sim_encoder_counts_per_rev"],
        friction_ripple=v["sim_friction_ripple"],
    )
    sims = []
    for channel in dict.fromkeys(s.channel for s in specs):
        devices = [(ActuatorPhysics(params, max_step_s=ROBOT_SIM_STEP_S), personalities[i])
                   for i, s in enumerate(specs) if s.channel == channel]  # fmt: skip
        settings = BusSettings(v["interface"], channel, v["bitrate"], fd)
        sims.append(SimulatedBus(devices, settings))
    return SimulatedBuses(sims).start()


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
    if v["protocol"] != "moteus":  # the parameter table refuses it first; never a default
        raise ValueError(f"protocol must be one of {list(PROTOCOLS)}, got {v['protocol']!r}")
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
    if v["sim_environment"] == "free":
        return None
    if v["sim_environment"] != "ball_on_rail":
        raise ValueError(
            "sim_environment must be one of ['free', 'ball_on_rail', 'drop_rig'], got "
            f"{v['sim_environment']!r}"
        )
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


def gain_error(proto: ActuatorProtocol | None, settings: DriverSettings) -> str | None:
    """Why the gains cannot be sent to this protocol's device, or None."""
    if isinstance(proto, MitProtocol):
        kp = settings.k_s_nm_per_rad / proto.gear_ratio**2
        kd = settings.k_d_nms_per_rad / proto.gear_ratio**2
        if kp > proto.limits.kp_max or kd > proto.limits.kd_max:
            return (
                f"k_s/k_d exceed the motor's MIT range kp <= {proto.limits.kp_max}, "
                f"kd <= {proto.limits.kd_max}"
            )
    if isinstance(proto, MoteusProtocol) and proto.kp_scale(settings.k_s_nm_per_rad) > 1.0:
        return "k_s exceeds the moteus's configured kp (kp_scale would be > 1)"
    return None
