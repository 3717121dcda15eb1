"""A drop-test bag as the discrepancy tool reads it (:class:`DropTrial`): the encoder, shuttle
height and load cell in seconds from the bag's first sample, the recorded contact, the release
and the fall's parabola; and the state a trial's impact piece starts from.

Rigs differ in what the bag contract leaves open, so a trial says what it found (``notes``):

* the strike's direction: the model turns the arm to negative theta (tip height r sin theta);
  a rig whose strike turns it to positive theta is analysed mirrored (theta -> -theta). The
  direction comes from ``custom_data`` ``transparency.strike_sign`` (+1 / -1) when the bag has
  it, else from the data (the arm's first swing after contact);
* a recording that starts during the fall (triggered near contact): the release is not recorded,
  and the fall is fitted from the part that is; its parabola's vertex stands for the release;
* no /joint_commands: theta_d is what the drive's recorded torque says it was, theta +
  effort / k_s at rest before contact (the impedance law); without efforts either, the arm's rest
  position (friction may hold the arm off theta_d, so that is a guess the notes say).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.reader import joint_series, open_bag, scalar_series
from transparency_ros.core.config import load_drop_test
from transparency_ros.core.errors import ModelError

LEAD_S = 0.003  # the impact piece starts this long before the recorded contact
AFTER_S = 0.25  # and lasts this long after it
REST_S = 0.05  # the stretch before the impact piece where the arm is at rest
SWING_S = 0.03  # the arm's first swing after contact, which shows the strike's direction
STRIKE_SIGN_KEY = "transparency.strike_sign"
MODEL_STRIKE_SIGN = -1  # the model's convention: a strike turns the arm to negative theta


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
    strike_sign: int = MODEL_STRIKE_SIGN  # the rig's: q and theta_d above are mirrored if +1
    release_recorded: bool = True  # False: the recording starts during the fall
    notes: tuple[str, ...] = ()  # what was assumed or detected, in words a user can act on
    # the drive's recorded torque at t_q in the model's theta sense (None: none recorded)
    effort: FloatArray | None = None

    @property
    def sense(self) -> float:
        """+1 where the trial is analysed as recorded, -1 where mirrored: what turns a torque
        in the rig's theta sense into the model's."""
        return float(self.strike_sign * MODEL_STRIKE_SIGN)

    @property
    def loaded_inertia_kgm2(self) -> float:
        """The arm's inertia with the shuttle on its tip, J_a + m r^2."""
        return self.arm_inertia_kgm2 + self.mass_kg * self.arm_m**2

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
        theta_d: float | None = None
        if "/joint_commands" in bag.topics:
            commands = joint_series(bag, "/joint_commands")
            finite = commands.position[np.isfinite(commands.position)]
            theta_d = float(finite[-1]) if finite.size else None
        declared = _declared_sign(bag.custom_data.get(STRIKE_SIGN_KEY), p)
    notes: list[str] = []
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
    held, release, fall, recorded = _release(t_h, h, contact, p)
    if not recorded:
        notes.append(
            f"the recording starts {contact - float(t_h[0]):.3g} s before contact, during the "
            "fall: the release is not recorded, the fall is fitted from the recorded part"
        )
    rest = float(np.median(q[t_q < contact - LEAD_S][-10:]))
    effort = states.effort[keep]
    if theta_d is None:
        theta_d = _setpoint_from_effort(t_q, q, effort, contact, numbers["transparency.k_s"])
        if theta_d is not None:
            notes.append(
                "no /joint_commands: theta_d from the recorded drive torque at rest before "
                f"contact (theta + effort / k_s), {theta_d:.4g} rad"
            )
        else:
            theta_d = rest
            notes.append(
                "no /joint_commands and no efforts: theta_d taken as the arm's rest position "
                f"before contact, {rest:.4g} rad (friction may hold the arm off it)"
            )
    sign = _strike_sign(t_q, q, rest, contact, declared, notes=notes)
    if sign != MODEL_STRIKE_SIGN:
        q, theta_d, effort = -q, -theta_d, -effort
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
        strike_sign=sign,
        release_recorded=recorded,
        notes=tuple(notes),
        effort=effort if np.isfinite(effort).any() else None,
    )


def _declared_sign(value: str | None, where: Path) -> int | None:
    if value is None:
        return None
    try:
        sign = int(float(value))
    except ValueError:
        sign = 0
    if sign not in (-1, 1):
        raise BagReadError(
            f"{where}: custom_data {STRIKE_SIGN_KEY} must be +1 or -1, got {value!r}"
        )
    return sign


def _strike_sign(
    t_q: FloatArray, q: FloatArray, rest: float, contact: float, declared: int | None,
    *, notes: list[str],
) -> int:  # fmt: skip
    """The direction a strike turns the arm: declared, or that of the largest excursion from
    rest in the first swing after contact (too small to tell: the model's)."""
    swing = q[(t_q >= contact) & (t_q <= contact + SWING_S)] - rest
    before = q[t_q < contact - LEAD_S][-50:]
    resolution = max(float(np.ptp(before)) if before.size else 0.0, 1e-9)
    peak = float(swing[np.argmax(np.abs(swing))]) if swing.size else 0.0
    seen = int(np.sign(peak)) if abs(peak) > 3 * resolution else 0
    turn = {1: "positive", -1: "negative"}
    if declared is not None:
        if seen and seen != declared:
            notes.append(
                f"the arm turned to {turn[seen]} theta after contact ({peak:+.3g} rad), opposite "
                f"to the declared {STRIKE_SIGN_KEY} {declared:+d}: check the encoder direction "
                "or the declared sign (analysed with the declared one)"
            )
        elif declared != MODEL_STRIKE_SIGN:
            notes.append(
                f"a strike turns this rig's arm to {turn[declared]} theta ({STRIKE_SIGN_KEY} "
                f"{declared:+d}): analysed mirrored (theta -> -theta)"
            )
        return declared
    if not seen:
        notes.append(
            f"the arm hardly moved after contact ({peak:+.3g} rad): the strike's direction is "
            f"taken as the model's ({turn[MODEL_STRIKE_SIGN]} theta); set {STRIKE_SIGN_KEY} "
            "if it is the other"
        )
        return MODEL_STRIKE_SIGN
    if seen != MODEL_STRIKE_SIGN:
        notes.append(
            f"a strike turns this rig's arm to {turn[seen]} theta (detected: {peak:+.3g} rad in "
            f"the first {SWING_S * 1e3:.0f} ms after contact); analysed mirrored "
            f"(theta -> -theta). Set {STRIKE_SIGN_KEY} to declare it"
        )
    return seen


def _release(
    t: FloatArray, h: FloatArray, contact: float, where: Path
) -> tuple[float, float, tuple[float, float, float, float] | None, bool]:
    """(held height, release time, the fall's parabola, whether the release is recorded). The
    fall under any constant force is a parabola h0 - a/2 (t - t_r)^2, so its vertex is the
    release: a quadratic fitted to the whole recorded fall (up to the impact piece) gives t_r
    without assuming g or a rail without friction, and the shuttle's state at the impact
    piece's start from all of the fall. A recording that starts during the fall has no hold: the
    vertex also gives the height it fell from."""
    first = t < t[0] + 0.02
    if np.count_nonzero(first) < 10:
        raise ModelError(f"{where}: fewer than 10 /shuttle/height samples in its first 20 ms")
    noise = float(np.median(np.abs(np.diff(h[first], n=2)))) / 0.6745 / math.sqrt(6)
    slope = float(np.polyfit(t[first] - t[0], h[first], 1)[0])
    falling = -slope * 0.02 > max(6 * noise, 1e-4)  # already moving: no hold recorded
    held = float(np.median(h[first]))
    if falling:
        start = 0
    else:
        gone = np.nonzero((h < held - max(6 * noise, 1e-4)) & (t < contact))[0]
        if gone.size == 0:
            raise ModelError(f"{where}: the shuttle never leaves its hold in /shuttle/height")
        start = int(gone[0])
    fit = (t >= t[start]) & (t < contact - LEAD_S)
    if np.count_nonzero(fit) < 10:
        if falling:
            raise ModelError(
                f"{where}: the recording starts {contact - float(t[0]):.3g} s before contact, "
                "too little of the fall to fit"
            )
        return held, float(t[start]), None, True
    mid = float(np.mean(t[fit]))
    c2, c1, c0 = (float(c) for c in np.polyfit(t[fit] - mid, h[fit], 2))
    if c2 >= 0:
        raise ModelError(f"{where}: the shuttle does not fall after the release")
    release = mid - c1 / (2 * c2)
    if falling:
        held = c0 - c1 * c1 / (4 * c2)  # the vertex: the height it fell from
    return held, release, (c2, c1, c0, mid), not falling


def _setpoint_from_effort(
    t_q: FloatArray, q: FloatArray, effort: FloatArray, contact: float, k_s: float
) -> float | None:
    """theta_d by the impedance law tau = k_s (theta_d - theta) from the last 50 ms before the
    impact piece's start, where the arm is at rest (the damping term is then nil); None when
    the recording has no efforts there or k_s is not positive."""
    sel = at_rest(t_q, contact) & np.isfinite(effort)
    if k_s <= 0 or np.count_nonzero(sel) < 5:
        return None
    return float(np.median(q[sel] + effort[sel] / k_s))


def at_rest(t_q: FloatArray, contact: float) -> npt.NDArray[np.bool_]:
    """The encoder samples of the last ``REST_S`` before the impact piece, where the arm is
    at rest (theta_d and the drive torque's noise are read there)."""
    return (t_q < contact - LEAD_S) & (t_q >= contact - LEAD_S - REST_S)


def spread(x: FloatArray) -> float:
    """A robust standard deviation of readings about their median (1.4826 times the median
    absolute deviation; 0 for none): a reading's noise where a few readings stand out."""
    return 1.4826 * float(np.median(np.abs(x - np.median(x)))) if x.size else 0.0


def mask_runs(mask: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """The runs of consecutive True in ``mask``, in order, as (first, last) indices."""
    on = np.flatnonzero(mask)
    if on.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(on) > 1)
    starts, ends = on[np.r_[0, breaks + 1]], on[np.r_[breaks, on.size - 1]]
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


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
