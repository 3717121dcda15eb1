"""A drop-test bag as the discrepancy tool reads it (:class:`DropTrial`): the encoder, shuttle
height and load cell in seconds from the bag's first sample, the recorded contact, the release
and the fall's parabola; and the state a trial's impact piece starts from."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.reader import joint_series, open_bag, scalar_series
from transparency_ros.core.config import load_drop_test
from transparency_ros.core.errors import ModelError

LEAD_S = 0.003  # the impact piece starts this long before the recorded contact
AFTER_S = 0.25  # and lasts this long after it


@dataclass(frozen=True)
class DropTrial:
    """One drop-test bag, times in seconds from the bag's first sample."""

    name: str
    actuator: str
    t_q: FloatArray  # encoder samples
    q: FloatArray
    t_h: FloatArray  # DAQ samples
    height: FloatArray  # shuttle contact face above the tip at rest [m]
    force: FloatArray  # load cell [N]
    theta_d: float
    k_s: float
    mass_kg: float
    arm_m: float
    arm_inertia_kgm2: float
    contact_s: float  # first load-cell sample above the threshold
    contact_end_s: float  # first sample after it back below the threshold
    release_s: float
    held_height_m: float
    # the fall's parabola h = c2 (t - mid)^2 + c1 (t - mid) + c0 as (c2, c1, c0, mid)
    fall: tuple[float, float, float, float] | None = None

    @property
    def start_s(self) -> float:
        return self.contact_s - LEAD_S

    @property
    def end_s(self) -> float:
        return min(self.contact_s + AFTER_S, float(self.t_q[-1]), float(self.t_h[-1]))


def load_drop_trial(path: str | Path) -> DropTrial:
    """A drop-test bag (README, "Bag contract") as a :class:`DropTrial`."""
    from transparency_ros.analysis.drop_eval import CUSTOM_KEYS  # noqa: PLC0415

    p = Path(path)
    with open_bag(p) as bag:
        custom = bag.require_custom(*CUSTOM_KEYS, "transparency.arm_inertia_kgm2")
        numbers: dict[str, float] = {}
        for key in (*CUSTOM_KEYS[1:], "transparency.arm_inertia_kgm2"):
            try:
                numbers[key] = float(custom[key])
            except ValueError:
                numbers[key] = math.nan
        bad = {k: custom[k] for k, v in numbers.items() if not math.isfinite(v)}
        if bad:
            raise BagReadError(f"{p}: custom_data must hold finite numbers, got {bad}")
        states = joint_series(bag, "/joint_states")
        force = scalar_series(
            bag, "/load_cell", "geometry_msgs/msg/WrenchStamped", "wrench.force.z"
        )
        height = scalar_series(bag, "/shuttle/height", "geometry_msgs/msg/PointStamped", "point.z")
        theta_d = 0.0
        if "/joint_commands" in bag.topics:
            commands = joint_series(bag, "/joint_commands")
            finite = commands.position[np.isfinite(commands.position)]
            theta_d = float(finite[-1]) if finite.size else 0.0
    keep = np.isfinite(states.position)
    t0_ns = int(min(states.stamp_ns[0], height.stamp_ns[0]))  # exact; seconds from there on
    t_q, q = states.seconds(t0_ns)[keep], states.position[keep]
    t_h, h = height.seconds(t0_ns), height.value
    f = np.interp(t_h, force.seconds(t0_ns), force.value)
    threshold = load_drop_test().contact_force_threshold_n
    above = np.nonzero(f > threshold)[0]
    if above.size == 0:
        raise BagReadError(f"{p}: /load_cell never exceeds {threshold} N: no contact to analyse")
    contact = float(t_h[above[0]])
    below = np.nonzero((t_h > contact) & (f <= threshold))[0]
    contact_end = float(t_h[below[0]]) if below.size else contact + 0.02
    if q.size < 20 or np.count_nonzero(t_q < contact - LEAD_S) < 5:
        raise BagReadError(f"{p}: /joint_states has too few samples before contact")
    held, release, fall = _release(t_h, h, contact, p)
    return DropTrial(
        name=f"{p.parent.name}/{p.name}",
        actuator=custom["transparency.actuator"],
        t_q=t_q,
        q=q,
        t_h=t_h,
        height=h,
        force=f,
        theta_d=theta_d,
        k_s=numbers["transparency.k_s"],
        mass_kg=numbers["transparency.shuttle_mass_kg"],
        arm_m=numbers["transparency.arm_length_m"],
        arm_inertia_kgm2=numbers["transparency.arm_inertia_kgm2"],
        contact_s=contact,
        contact_end_s=contact_end,
        release_s=release,
        held_height_m=held,
        fall=fall,
    )


def _release(
    t: FloatArray, h: FloatArray, contact: float, where: Path
) -> tuple[float, float, tuple[float, float, float, float] | None]:
    """(held height, release time, the fall's parabola). The fall under any constant force is
    a parabola h0 - a/2 (t - t_r)^2, so its vertex is the release: a quadratic fitted to the
    whole fall (up to the impact piece) gives t_r without assuming g or a rail without
    friction, and the shuttle's state at the impact piece's start from all of the fall."""
    first = t < t[0] + 0.02
    held = float(np.median(h[first]))
    noise = float(np.median(np.abs(np.diff(h[first], n=2)))) / 0.6745 / math.sqrt(6)
    gone = np.nonzero((h < held - max(6 * noise, 1e-4)) & (t < contact))[0]
    if gone.size == 0 or np.count_nonzero(first) < 10:
        raise ModelError(f"{where}: no hold before the release in /shuttle/height")
    fit = (t >= t[gone[0]]) & (t < contact - LEAD_S)
    if np.count_nonzero(fit) < 10:
        return held, float(t[gone[0]]), None
    mid = float(np.mean(t[fit]))
    c2, c1, c0 = (float(c) for c in np.polyfit(t[fit] - mid, h[fit], 2))
    if c2 >= 0:
        raise ModelError(f"{where}: the shuttle does not fall after the release")
    return held, mid - c1 / (2 * c2), (c2, c1, c0, mid)


def rest_position(trial: DropTrial) -> float:
    """The motor position at rest before the impact piece (median of the last 10 samples)."""
    before = trial.q[trial.t_q < trial.start_s]
    return float(np.median(before[-10:]))


def shuttle_state(trial: DropTrial) -> tuple[float, float]:
    """Height and velocity at the impact piece's start: from the fall's parabola, or a
    quadratic over the 15 ms before when the fall is too short to fit."""
    if trial.fall is not None:
        c2, c1, c0, mid = trial.fall
        dt = trial.start_s - mid
        return c2 * dt * dt + c1 * dt + c0, 2 * c2 * dt + c1
    sel = (trial.t_h >= trial.start_s - 0.015) & (trial.t_h < trial.start_s)
    if np.count_nonzero(sel) < 5:
        raise ModelError(f"{trial.name}: too few shuttle samples before contact")
    coef = np.polyfit(trial.t_h[sel] - trial.start_s, trial.height[sel], 2)
    return float(coef[2]), float(coef[1])
