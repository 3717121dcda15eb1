"""Generate drop-test campaigns (Sec. 3.1) with hidden effects, as bags of the bag contract.

The truth is integrated here with the project's actuator physics
(:class:`~transparency_ros.core.actuator_physics.ActuatorPhysics`: backlash, stick-slip friction,
encoder resolution, friction ripple, 20 us substeps) and a shuttle written for this generator:
collisions are instant (Newton's law with the hidden ``restitution``; none by default: the
shuttle stays on the arm) unless ``structural_compliance`` makes the contact a spring-damper
(damped for the restitution); rail friction; the shuttle's weight on the arm only when
``payload_gravity`` is hidden. With nothing hidden this is eq. (2) of the paper. Sensors as on
the rig: encoder at 1 kHz (with ``sensor_delay``, ``quantization``), load cell (the mean force
over each sample period) and potentiometer at 10 kHz with noise. Labels go to a separate file
the tool never reads.
"""

from __future__ import annotations

import json
import math
import random
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from transparency_ros.core.actuator_physics import ActuatorPhysics, ImpedanceLaw, PhysicsParams
from transparency_ros.core.config import get_actuator, load_drop_test
from transparency_ros.core.contact_model import restitution_damping_ratio
from transparency_ros.synth.campaign import draw_hidden

GRAVITY = 9.81
EFFECTS = (
    "payload_gravity",
    "restitution",
    "impact_speed_loss",
    "structural_compliance",
    "backlash",
    "stiction",
    "sensor_delay",
    "quantization",
    "torque_offset",
    "parameter_drift",
)
OUTSIDE = "friction_ripple"  # not in the tool's library: must come out unexplained
ACTUATORS = ("U10DD", "EC60", "T2822", "U10GB")
HEIGHTS_M = (0.05, 0.1, 0.2, 0.35, 0.5, 0.8)
BASE_STAMP_S = 1.7e9

_SAMPLERS: dict[str, Any] = {
    "payload_gravity": lambda r, m, arm: {"mgl_nm": m * GRAVITY * arm},
    "restitution": lambda r, m, arm: {"coefficient": r.uniform(0.3, 0.6)},
    "impact_speed_loss": lambda r, m, arm: {"rail_friction_n": r.uniform(0.4, 1.2)},
    "structural_compliance": lambda r, m, arm: {"stiffness_n_per_m": r.uniform(2e4, 1e5)},
    "backlash": lambda r, m, arm: {"backlash_rad": math.radians(r.uniform(0.8, 2.0))},
    "stiction": lambda r, m, arm: {"static_nm": r.uniform(0.3, 0.5)},
    "sensor_delay": lambda r, m, arm: {"delay_s": r.uniform(0.003, 0.008)},
    # an 11- or 12-bit magnetic encoder on the output
    "quantization": lambda r, m, arm: {"step_rad": 2 * math.pi / r.choice([2048, 4096])},
    "torque_offset": lambda r, m, arm: {"offset_nm": r.choice([-1, 1]) * r.uniform(0.08, 0.15)},
    "parameter_drift": lambda r, m, arm: {"viscous_scale": r.uniform(1.8, 2.5)},
    OUTSIDE: lambda r, m, arm: {"ripple": r.uniform(0.6, 0.8), "cycles_per_rev": 40.0},
}


@dataclass
class Shuttle:
    """The shuttle on its rail against the arm tip, as an environment of the actuator physics."""

    mass_kg: float
    arm_m: float
    arm_inertia_kgm2: float
    height_m: float
    stiffness_n_per_m: float
    restitution: float
    weight_on_arm: bool
    rail_friction_n: float
    compliant: bool  # a spring contact; otherwise collisions are instant (see strike())
    velocity_m_s: float = 0.0
    force_n: float = 0.0
    impulse_ns: float = 0.0  # integral of the contact force: the load cell averages over a sample
    released: bool = False
    on_arm: bool = False
    _last_s: float | None = None
    _cos2: float = 1.0  # cos^2 of the arm's angle at the last torque_nm call
    # the tip's height at rest, r sin(q) at the release: heights are above it (the bag contract)
    tip_rest_m: float | None = None

    @property
    def damping_ns_per_m(self) -> float:
        zeta = float(restitution_damping_ratio(min(max(self.restitution, 1e-3), 0.999)))
        return 2 * zeta * math.sqrt(self.stiffness_n_per_m * self.mass_kg)

    @property
    def inertia_kgm2(self) -> float:
        """The arm, and the shuttle while it rides the tip on its vertical rail: m r^2 cos^2 q
        (read each substep, at the angle of the substep before)."""
        riding = self.mass_kg * self.arm_m**2 * self._cos2 if self.on_arm else 0.0
        return self.arm_inertia_kgm2 + riding

    def torque_nm(self, position_rad: float, velocity_rad_s: float, time_s: float) -> float:
        dt = 0.0 if self._last_s is None else time_s - self._last_s
        self._last_s = time_s
        r, m = self.arm_m, self.mass_kg
        cos = math.cos(position_rad)
        self._cos2 = cos * cos
        if self.released and self.tip_rest_m is None:
            self.tip_rest_m = r * math.sin(position_rad)
        tip_y = r * math.sin(position_rad) - (self.tip_rest_m or 0.0)
        tip_v = r * cos * velocity_rad_s
        weight = m * GRAVITY if self.weight_on_arm else 0.0
        if self.on_arm:  # rides on the tip (y = r sin q): exact at any angle
            self.height_m, self.velocity_m_s = tip_y, tip_v
            rail = self.rail_friction_n * (1.0 if tip_v > 0 else -1.0 if tip_v < 0 else 0.0)
            self.force_n = weight
            self.impulse_ns += weight * dt
            riding = m * r * r * cos * math.sin(position_rad) * velocity_rad_s**2
            return -(weight + rail) * r * cos + riding
        if not self.released:
            return 0.0
        pen = tip_y - self.height_m if self.compliant else 0.0
        rel = tip_v - self.velocity_m_s
        force = 0.0
        if pen > 0:
            force = max(0.0, self.stiffness_n_per_m * pen + self.damping_ns_per_m * rel)
        self.force_n = force
        self.impulse_ns += force * dt
        acc = (force - (weight if pen > 0 else m * GRAVITY)) / m
        if self.velocity_m_s != 0.0:
            acc -= math.copysign(self.rail_friction_n / m, self.velocity_m_s)
        self.velocity_m_s += acc * dt
        self.height_m += self.velocity_m_s * dt
        return -force * r * cos

    def strike(self, physics: ActuatorPhysics) -> None:
        """An instant collision (Newton's law with the restitution) when the falling shuttle
        meets the tip: momentum exchanged with the body the tip belongs to (the arm, and the
        motor when the gearbox is engaged). A rebound slower than 5 cm/s ends the bouncing:
        the shuttle stays on the arm."""
        s = physics.state
        if self.compliant or self.on_arm or not self.released:
            return
        r, m = self.arm_m, self.mass_kg
        cos = math.cos(s.load_position_rad)
        tip_y = r * math.sin(s.load_position_rad) - (self.tip_rest_m or 0.0)
        tip_v = r * cos * s.load_velocity_rad_s
        u = self.velocity_m_s - tip_v
        if self.height_m > tip_y or u >= 0:
            return
        engaged = s.engaged_side != 0
        inertia = self.arm_inertia_kgm2 + (physics.params.rotor_inertia_kgm2 if engaged else 0.0)
        big_m = inertia / (r * cos) ** 2
        e = self.restitution if abs(u) * self.restitution >= 0.05 else 0.0
        v_new = self.velocity_m_s - (1 + e) * big_m / (m + big_m) * u
        w_new = (tip_v + (1 + e) * m / (m + big_m) * u) / (r * cos)
        self.impulse_ns += m * abs(v_new - self.velocity_m_s)
        # the bodies met tau ago (checked every substep): from then on at the new velocities
        tau = (tip_y - self.height_m) / max(tip_v - self.velocity_m_s, 1e-9)
        shift = (w_new - s.load_velocity_rad_s) * tau
        self.velocity_m_s = v_new
        self.height_m = tip_y - tip_v * tau + v_new * tau
        s.load_velocity_rad_s = w_new
        s.load_position_rad += shift
        if engaged:
            s.motor_velocity_rad_s = w_new
            s.motor_position_rad += shift
        if e == 0.0:
            self.on_arm = True


def draw_effect(name: str, rng: random.Random, mass_kg: float, arm_m: float) -> dict[str, float]:
    return dict(_SAMPLERS[name](rng, mass_kg, arm_m))


def simulate_drop(
    actuator: str,
    height_m: float,
    hidden: dict[str, dict[str, float]],
    seed: int,
    *,
    hold_s: float = 0.05,
    after_s: float = 0.3,
) -> dict[str, np.ndarray]:
    """One trial: encoder (t, q) at 1 kHz and DAQ (t, height, force) at 10 kHz."""
    a = get_actuator(actuator)
    drop = load_drop_test()
    m, r = drop.shuttle_mass_for(actuator), drop.arm_length_m
    drift = hidden.get("parameter_drift", {}).get("viscous_scale", 1.0)
    quant = hidden.get("quantization", {}).get("step_rad")
    counts = round(2 * math.pi / quant / float(a.reduction_ratio)) if quant else 2**22
    params = PhysicsParams(
        rotor_inertia_kgm2=a.reflected_inertia_kgm2,
        static_friction_nm=max(
            a.coulomb_friction_nm, hidden.get("stiction", {}).get("static_nm", 0)
        ),
        coulomb_friction_nm=a.coulomb_friction_nm,
        viscous_nms_per_rad=a.viscous_damping_nms_per_rad * drift,
        backlash_rad=hidden.get("backlash", {}).get("backlash_rad", 0.0),
        torque_limit_nm=a.peak_torque_nm,
        encoder_counts_per_rev=counts,
        reduction=float(a.reduction_ratio),
        friction_ripple=hidden.get(OUTSIDE, {}).get("ripple", 0.0),
        friction_ripple_cycles_per_rev=hidden.get(OUTSIDE, {}).get("cycles_per_rev", 1.0),
    )
    compliant = "structural_compliance" in hidden
    shuttle = Shuttle(
        mass_kg=m,
        arm_m=r,
        arm_inertia_kgm2=drop.arm_inertia_kgm2,
        height_m=height_m,
        stiffness_n_per_m=hidden.get("structural_compliance", {}).get("stiffness_n_per_m", 0.0),
        restitution=hidden.get("restitution", {}).get("coefficient", 0.0),
        weight_on_arm="payload_gravity" in hidden,
        rail_friction_n=hidden.get("impact_speed_loss", {}).get("rail_friction_n", 0.0),
        compliant=compliant,
    )
    physics = ActuatorPhysics(params, shuttle, max_step_s=2e-5)
    offset = hidden.get("torque_offset", {}).get("offset_nm", 0.0)
    law = ImpedanceLaw(drop.k_s_nm_per_rad, 0.0, 0.0, 0.0, offset)
    # the arm at rest before the drop, as a rig waits for it: where the offset holds it
    rest = offset / drop.k_s_nm_per_rad
    physics.state.motor_position_rad = physics.state.load_position_rad = rest
    rng = np.random.default_rng(seed)
    fall_s = math.sqrt(2 * height_m / GRAVITY) * 1.1
    total = hold_s + fall_s + after_s
    n = round(total * 10_000)
    t_daq = np.arange(n) / 10_000
    q_true, h, f = np.empty(n), np.empty(n), np.empty(n)
    impulse = 0.0
    for k in range(n):
        if k == round(hold_s * 10_000):
            shuttle.released = True
        # the load cell's anti-alias filter: the mean force over the last sample period (a
        # light arm's impact lasts less than one period)
        q_true[k], h[k] = physics.measured_position_rad, shuttle.height_m
        f[k] = (shuttle.impulse_ns - impulse) / 1e-4
        impulse = shuttle.impulse_ns
        for _ in range(5):
            physics.advance(2e-5, law)
            shuttle.strike(physics)
    delay = hidden.get("sensor_delay", {}).get("delay_s", 0.0)
    t_q = t_daq[::10]
    q = np.interp(t_q - delay, t_daq, q_true, left=0.0)
    return {
        "t_q": t_q,
        "q": q,
        "t_daq": t_daq,
        "height": h + rng.normal(0, 2e-5, n),
        "force": f + rng.normal(0, 0.05, n),
    }


def write_drop_campaign(
    out: Path,
    seed: int,
    *,
    hidden: Sequence[str] | None = None,
    actuator: str | None = None,
    heights: Sequence[float] = HEIGHTS_M,
) -> Path:
    """One bag per height under ``out/bags``; labels in ``out/labels.json``."""
    from transparency_ros.bag.writer import BagWriter, message_types, time_msg  # noqa: PLC0415

    rng = random.Random(seed)
    actuator = actuator or rng.choice(ACTUATORS)
    if hidden is None:
        hidden = draw_hidden(rng, EFFECTS, OUTSIDE)
    drop = load_drop_test()
    m, r = drop.shuttle_mass_for(actuator), drop.arm_length_m
    truth = {name: draw_effect(name, rng, m, r) for name in hidden}
    types = message_types()
    custom = {
        "transparency.trial": "drop_test",
        "transparency.actuator": actuator,
        "transparency.k_s": str(drop.k_s_nm_per_rad),
        "transparency.k_d": "0.0",
        "transparency.threshold_rad": str(drop.threshold_rad),
        "transparency.shuttle_mass_kg": str(m),
        "transparency.arm_length_m": str(r),
        "transparency.arm_inertia_kgm2": str(drop.arm_inertia_kgm2),
    }
    header = types["std_msgs/msg/Header"]

    def joint(ns: int, position: float, effort: float) -> Any:
        return types["sensor_msgs/msg/JointState"](
            header=header(stamp=time_msg(ns), frame_id=""),
            name=["joint"],
            position=np.array([position]),
            velocity=np.zeros(1),
            effort=np.array([effort]),
        )

    for i, height in enumerate(heights):
        data = simulate_drop(actuator, height, truth, seed * 100 + i)
        bag = out / "bags" / actuator / f"h{height * 1000:06.1f}mm"
        with BagWriter(bag, custom | {"transparency.drop_height_m": str(height)}) as w:
            w.add("/joint_states", "sensor_msgs/msg/JointState")
            w.add("/joint_commands", "sensor_msgs/msg/JointState")
            w.add("/load_cell", "geometry_msgs/msg/WrenchStamped")
            w.add("/shuttle/height", "geometry_msgs/msg/PointStamped")
            ns0 = round(BASE_STAMP_S * 1e9)

            w.write_message("/joint_commands", ns0, joint(ns0, 0.0, 0.0))  # theta_d = 0
            for t, q in zip(data["t_q"], data["q"], strict=True):
                ns = ns0 + round(t * 1e9)
                w.write_message("/joint_states", ns, joint(ns, q, -drop.k_s_nm_per_rad * q))
            vec, wrench = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Wrench"]
            point = types["geometry_msgs/msg/Point"]
            for t, h, f in zip(data["t_daq"], data["height"], data["force"], strict=True):
                ns = ns0 + round(t * 1e9)
                stamp = header(stamp=time_msg(ns), frame_id="")
                w.write_message(
                    "/load_cell",
                    ns,
                    types["geometry_msgs/msg/WrenchStamped"](
                        header=stamp,
                        wrench=wrench(
                            force=vec(x=0.0, y=0.0, z=f), torque=vec(x=0.0, y=0.0, z=0.0)
                        ),
                    ),
                )
                w.write_message(
                    "/shuttle/height",
                    ns,
                    types["geometry_msgs/msg/PointStamped"](
                        header=stamp, point=point(x=0.0, y=0.0, z=h)
                    ),
                )
    labels = out / "labels.json"  # never read by the tool
    labels.write_text(json.dumps({"seed": seed, "actuator": actuator, "hidden": truth}, indent=2))
    return out
