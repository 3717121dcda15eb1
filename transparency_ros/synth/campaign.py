"""Generate 1-DoF torque-driven campaigns (a pendulum on an actuator) with hidden effects.

The truth is integrated here, independently of the tool's model, at 10 kHz with explicit
stick-slip friction, then sampled at the sensor rate with realistic noise: position from an
encoder (quantized to 2^14 counts per revolution unless the effect says otherwise) with jitter,
velocity by finite differences, torque as commanded plus current-sensor noise. Inputs are
multisine torques rich enough to excite every effect. Labels (the hidden effects and their true
parameters) go to a separate file the tool never reads.
"""

from __future__ import annotations

import json
import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

EFFECTS = (
    "torque_offset",
    "cogging",
    "payload_gravity",
    "stiction",
    "torque_saturation",
    "sensor_delay",
    "parameter_drift",
)
OUTSIDE = "torque_ripple_with_speed"  # not in the tool's library: must come out unexplained


@dataclass(frozen=True)
class Plant:
    inertia_kgm2: float = 0.05
    viscous_nms_per_rad: float = 0.08
    coulomb_nm: float = 0.15
    gravity_nm: float = 1.5
    hidden: dict[str, dict[str, float]] = field(default_factory=dict)


_SAMPLERS = {
    "torque_offset": lambda r: {"offset_nm": r.choice([-1, 1]) * r.uniform(0.15, 0.4)},
    "cogging": lambda r: {
        "amplitude_nm": r.uniform(0.15, 0.35),
        "cycles_per_rev": float(r.choice([6, 12, 21])),
        "phase_rad": r.uniform(-math.pi, math.pi),
    },
    "payload_gravity": lambda r: {
        "mgl_nm": r.uniform(0.3, 0.8),
        "offset_rad": r.uniform(-0.5, 0.5),
    },
    "stiction": lambda r: {"static_nm": r.uniform(0.4, 0.7)},
    "torque_saturation": lambda r: {"limit_nm": r.uniform(1.2, 1.8)},
    "sensor_delay": lambda r: {"delay_s": r.uniform(0.006, 0.015)},
    "parameter_drift": lambda r: {"viscous_scale": r.uniform(2.0, 3.0)},
    OUTSIDE: lambda r: {"amplitude_nm": r.uniform(0.3, 0.5), "frequency_hz": r.uniform(4.0, 8.0)},
}


def draw_hidden(rng: random.Random, effects: Sequence[str], outside: str) -> list[str]:
    """Which effects a campaign hides: one (half the time), a pair, none, or the outside one."""
    kind = rng.choice(["single", "single", "single", "pair", "none", "outside"])
    if kind == "single":
        return [rng.choice(effects)]
    if kind == "pair":
        return rng.sample(list(effects), 2)
    return [] if kind == "none" else [outside]


def draw_effect(name: str, rng: random.Random) -> dict[str, float]:
    """Random true parameters of a hidden effect."""
    sampler: Any = _SAMPLERS[name]
    return dict(sampler(rng))


def _input(t: np.ndarray, rng: random.Random, amplitude: float) -> np.ndarray:
    tau = np.zeros_like(t)
    for _ in range(5):
        f = rng.uniform(0.2, 3.0)
        tau += rng.uniform(0.3, 1.0) * np.sin(2 * math.pi * f * t + rng.uniform(0, 2 * math.pi))
    # pauses: the torque fades to nothing now and then, so the joint can stick and reverse
    envelope = 0.5 * (1 + np.sin(2 * math.pi * rng.uniform(0.15, 0.3) * t + rng.uniform(0, 6.3)))
    return np.asarray(amplitude * envelope**2 * tau / np.max(np.abs(tau)), dtype=float)


def simulate_trial(
    plant: Plant, tau_cmd: np.ndarray, rate_hz: float, rng: random.Random, substeps: int = 10
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    h = plant.hidden
    n = tau_cmd.size
    dt = 1.0 / rate_hz / substeps
    j = plant.inertia_kgm2
    b = plant.viscous_nms_per_rad * h.get("parameter_drift", {}).get("viscous_scale", 1.0)
    q, qd = rng.uniform(-0.5, 0.5), 0.0
    qs, qds = np.empty(n), np.empty(n)
    static = h.get("stiction", {}).get("static_nm", 0.0)
    for k in range(n):
        tau = tau_cmd[k]
        if "torque_saturation" in h:
            lim = h["torque_saturation"]["limit_nm"]
            tau = max(-lim, min(lim, tau))
        for s in range(substeps):
            t_now = (k * substeps + s) * dt
            drive = tau + h.get("torque_offset", {}).get("offset_nm", 0.0)
            if "cogging" in h:
                c = h["cogging"]
                drive += c["amplitude_nm"] * math.sin(c["cycles_per_rev"] * q + c["phase_rad"])
            if "payload_gravity" in h:
                g = h["payload_gravity"]
                drive -= g["mgl_nm"] * math.sin(q + g["offset_rad"])
            if OUTSIDE in h:
                o = h[OUTSIDE]
                drive += (
                    o["amplitude_nm"]
                    * math.sin(2 * math.pi * o["frequency_hz"] * t_now)
                    * min(1.0, abs(qd))
                )
            drive -= plant.gravity_nm * math.sin(q)
            if qd == 0.0 and abs(drive) <= max(static, plant.coulomb_nm):
                qs_k = 0.0
            else:
                net = drive - plant.coulomb_nm * math.copysign(1.0, qd if qd != 0 else drive)
                new = (qd + net / j * dt) / (1 + b * dt / j)
                qs_k = 0.0 if qd != 0 and new * qd < 0 and static > 0 else new
            qd = qs_k
            q += qd * dt
        qs[k], qds[k] = q, qd
    return qs, qds, tau_cmd, np.arange(n) / rate_hz


def write_campaign(
    out: Path,
    seed: int,
    *,
    trials: int = 10,
    seconds: float = 6.0,
    rate_hz: float = 500.0,
    hidden: Sequence[str] | None = None,
) -> Path:
    """Write trials as CSV (time, position, velocity, torque) and labels.json apart."""
    rng = random.Random(seed)
    if hidden is None:
        hidden = draw_hidden(rng, EFFECTS, OUTSIDE)
    plant = Plant(hidden={name: draw_effect(name, rng) for name in hidden})
    data = out / "data"
    data.mkdir(parents=True, exist_ok=True)
    delay = plant.hidden.get("sensor_delay", {}).get("delay_s", 0.0)
    step = 2 * math.pi / 16384
    for i in range(trials):
        t = np.arange(round(seconds * rate_hz)) / rate_hz
        tau = _input(t, rng, amplitude=rng.uniform(1.5, 2.5))
        q, _qd, _, _ = simulate_trial(plant, tau, rate_hz, rng)
        if delay:
            q = np.interp(t - delay, t, q, left=q[0])
        q_meas = (
            np.round((q + np.random.default_rng(seed * 1000 + i).normal(0, 2e-5, q.size)) / step)
            * step
        )
        qd_meas = np.gradient(q_meas, t)
        tau_meas = tau + np.random.default_rng(seed * 1000 + i + 500).normal(0, 0.01, t.size)
        np.savetxt(
            data / f"trial_{i:02d}.csv",
            np.c_[t, q_meas, qd_meas, tau_meas],
            delimiter=",",
            header="time,position,velocity,torque",
            comments="",
        )
    nominal = out / "nominal.yaml"
    nominal.write_text(
        f"inertia_kgm2: {plant.inertia_kgm2}\nviscous_nms_per_rad: {plant.viscous_nms_per_rad}\n"
        f"coulomb_nm: {plant.coulomb_nm}\ngravity_nm: {plant.gravity_nm}\n"
    )
    labels = out / "labels.json"  # never read by the tool
    labels.write_text(json.dumps({"seed": seed, "hidden": plant.hidden}, indent=2))
    return out
