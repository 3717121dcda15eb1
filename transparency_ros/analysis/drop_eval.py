"""Drop-test evaluation from bags that follow the bag contract (README, "Bag contract").

Per trial, as in Sec. 3.1 of the paper:
* t_t: first load-cell sample above ``contact_force_threshold_n`` (1 N);
* T = 1/2 m_s v_s,t^2, with v_s,t from a quadratic fitted to the shuttle height over the
  ``fit_window_s`` before t_t (free fall: the fit removes the potentiometer noise);
* t_e: the first recorded /contact onset after t_t, or, in a bag without one, the estimator
  replayed offline on /joint_states (eq. 1 and the threshold of the bag's custom_data);
* t_r = t_e - t_t; v_s,e from a local quadratic fit of the height around t_e;
* stamps are compared as integer nanoseconds (t_t_ns, t_e_ns are header stamps, exact) and
  become float seconds only as differences;
* Delta E = 1/2 m_s (v_s,t^2 - v_s,e^2) (eq. 4); F_mu = the load cell at t_e; F_est = tau_hat / r.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.keys import INTERRUPTED_KEY
from transparency_ros.bag.reader import (
    BagSource,
    find_bags,
    joint_series,
    open_bag,
    scalar_series,
    stamp_ns,
)
from transparency_ros.core import stamps
from transparency_ros.core.config import load_drop_test
from transparency_ros.core.estimator import (
    DetectorSettings,
    EstimatorGains,
    EstimatorPipeline,
    EventKind,
    SchmittDetector,
)

CUSTOM_KEYS = (
    "transparency.actuator",
    "transparency.k_s",
    "transparency.threshold_rad",
    "transparency.shuttle_mass_kg",
    "transparency.arm_length_m",
    "transparency.drop_height_m",
)


@dataclass(frozen=True)
class TrialMetrics:
    bag: str
    actuator: str
    drop_height_m: float
    shuttle_mass_kg: float
    t_t_s: float | None  # ROS time of true contact [s] (display; t_t_ns is exact)
    energy_j: float | None  # T
    v_s_t_m_s: float | None
    detected: bool
    estimate_source: str  # "recorded /contact", "offline estimator", or "none"
    t_r_s: float | None
    v_s_e_m_s: float | None
    delta_e_j: float | None
    f_measured_n: float | None  # load cell at t_e
    f_estimated_n: float | None  # tau_hat / r at t_e
    t_t_ns: int | None = None  # stamp of the load-cell sample of true contact
    t_e_ns: int | None = None  # stamp of the sample that crossed the threshold

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _quadratic_velocity(t: np.ndarray, h: np.ndarray, at_s: float) -> float:
    coef = np.polyfit(t - at_s, h, 2)
    return float(coef[1])  # d/dt at t = at_s


def offline_onset(bag: BagSource, k_s: float, threshold: float) -> tuple[int, float] | None:
    """(stamp [ns], tau_hat) of the first onset of the estimator replayed on /joint_states."""
    states = joint_series(bag, "/joint_states")
    theta_d = 0.0
    if "/joint_commands" in bag.topics:
        commands = joint_series(bag, "/joint_commands")
        finite = np.isfinite(commands.position)
        if finite.any():
            theta_d = float(commands.position[finite][-1])
    # the estimator node's own core, as it would have run on these samples
    pipeline = EstimatorPipeline(
        gains=EstimatorGains(k_s_nm_per_rad=k_s),
        detector=SchmittDetector(
            DetectorSettings(contact_onset=threshold, contact_release=threshold / 2)
        ),
        default_theta_d_rad=theta_d,
    )
    velocity = np.nan_to_num(states.velocity)
    for stamp, position, speed in zip(states.stamp_ns, states.position, velocity, strict=True):
        _, events = pipeline.sample(int(stamp), ["joint"], [float(position)], [float(speed)])
        for event in events:
            if event.kind is EventKind.CONTACT_ONSET:
                return event.stamp_ns, event.torque_nm
    return None


class IncompleteTrialError(BagReadError):
    """A trial's bag closed by Ctrl-C or SIGTERM during the trial: not evaluated."""


def evaluate_trial(path: str | Path, fit_window_s: float = 0.015) -> TrialMetrics:
    drop = load_drop_test()
    with open_bag(path) as bag:
        interrupted = bag.custom_data.get(INTERRUPTED_KEY)
        if interrupted is not None:
            raise IncompleteTrialError(f"{path}: recorded until {interrupted}, an incomplete trial")
        custom = bag.require_custom(*CUSTOM_KEYS)
        actuator = custom["transparency.actuator"]
        try:
            k_s = float(custom["transparency.k_s"])
            threshold = float(custom["transparency.threshold_rad"])
            mass = float(custom["transparency.shuttle_mass_kg"])
            arm = float(custom["transparency.arm_length_m"])
            height = float(custom["transparency.drop_height_m"])
        except ValueError as err:
            raise BagReadError(f"{path}: custom_data value is not a number: {err}") from err
        force = scalar_series(
            bag, "/load_cell", "geometry_msgs/msg/WrenchStamped", "wrench.force.z"
        )
        shuttle = scalar_series(bag, "/shuttle/height", "geometry_msgs/msg/PointStamped", "point.z")
        above = np.nonzero(force.value > drop.contact_force_threshold_n)[0]
        none = TrialMetrics(str(path), actuator, height, mass, None, None, None, False, "none",
                            None, None, None, None, None)  # fmt: skip
        if above.size == 0:
            return none
        t_t_ns = int(force.stamp_ns[above[0]])
        # windows are chosen on exact nanosecond differences (no sample flips in or out with
        # the rounding of epoch seconds); the fits then run in seconds since t_t
        since_ns = shuttle.stamp_ns - t_t_ns
        t_shuttle = since_ns * 1e-9
        before = (since_ns >= -round(fit_window_s * 1e9)) & (since_ns < -200_000)
        if np.count_nonzero(before) < 10:
            raise BagReadError(f"{path}: /shuttle/height has too few samples before contact")
        v_t = _quadratic_velocity(t_shuttle[before], shuttle.value[before], 0.0)
        energy = 0.5 * mass * v_t**2
        onset: tuple[int, float] | None = None
        source = "none"
        if "/contact" in bag.topics and bag.topics["/contact"].count > 0:
            for _topic, _log, msg in bag.messages(["/contact"]):
                stamp = stamp_ns(msg.header)
                if stamp >= t_t_ns - 2_000_000:  # 2 ms
                    onset, source = (stamp, float(msg.wrench.torque.z)), "recorded /contact"
                    break
        if onset is None:
            onset = offline_onset(bag, k_s, threshold)
            source = "offline estimator" if onset is not None else "none"
    t_t = t_t_ns / stamps.NS_PER_S
    base = TrialMetrics(str(path), actuator, height, mass, t_t, energy, v_t, False, source,
                        None, None, None, None, None, t_t_ns)  # fmt: skip
    if onset is None:
        return base
    t_e_ns, tau_hat = onset
    t_r = (t_e_ns - t_t_ns) * 1e-9
    near = np.abs(since_ns - (t_e_ns - t_t_ns)) <= 1_000_000  # 1 ms
    v_e = (
        _quadratic_velocity(t_shuttle[near], shuttle.value[near], t_r)
        if near.sum() >= 5
        else math.nan
    )
    f_mu = float(np.interp(t_r, force.seconds(t_t_ns), force.value))
    return TrialMetrics(str(path), actuator, height, mass, t_t, energy, v_t, True, source,
                        t_r, v_e, 0.5 * mass * (v_t**2 - v_e**2), f_mu,
                        abs(tau_hat) / arm, t_t_ns, t_e_ns)  # fmt: skip


def evaluate(
    paths: Sequence[str | Path],
    progress: Callable[[int, int, Path], None] = lambda *_: None,
    skipped: Callable[[BagReadError], None] | None = None,
) -> list[TrialMetrics]:
    """Every trial under ``paths``; a bag that cannot be evaluated (interrupted, damaged,
    not a drop test) is passed to ``skipped`` and the rest evaluated (raised when ``skipped``
    is None, so none is ever dropped silently)."""
    bags = find_bags(paths)
    results = []
    for i, bag in enumerate(bags, 1):
        progress(i, len(bags), bag)
        try:
            results.append(evaluate_trial(bag))
        except BagReadError as err:
            if skipped is None:
                raise
            skipped(err)
    return results


@dataclass(frozen=True)
class ActuatorSummary:
    actuator: str
    trials: int
    detected: int
    min_detected_energy_j: float | None  # smallest T among detected trials
    max_missed_energy_j: float | None  # largest T among missed trials
    delta_e_slope: float | None  # least-squares slope of Delta E vs T (detected trials)
    model_min_detectable_energy_j: float
    model_delta_e_slope: float
    t_r_error_median_ms: float | None  # measured - model, median over detected trials


def summarise(results: Sequence[TrialMetrics]) -> list[ActuatorSummary]:
    from transparency_ros.analysis.fig2 import model_curves  # noqa: PLC0415
    from transparency_ros.core.contact_model import model_for  # noqa: PLC0415

    out = []
    table1 = ("U10DD", "EC60", "T2822", "U10GB")
    names = sorted(
        dict.fromkeys(r.actuator for r in results),
        key=lambda a: (table1.index(a) if a in table1 else len(table1), a),
    )
    for actuator in names:
        rows = [r for r in results if r.actuator == actuator]
        hit = [
            r
            for r in rows
            if r.detected and r.energy_j is not None and r.delta_e_j is not None
            and math.isfinite(r.delta_e_j)
        ]  # fmt: skip
        miss = [r for r in rows if not r.detected and r.energy_j is not None]
        energies = np.array([r.energy_j for r in hit], dtype=float)
        losses = np.array([r.delta_e_j for r in hit], dtype=float)
        model = model_for(actuator)
        curve = model_curves([model])[0]
        slope = float(np.polyfit(energies, losses, 1)[0]) if len(hit) >= 2 else None
        errors = []
        predicted = model.solve(energies) if hit else None
        for i, r in enumerate(hit):
            if predicted is not None and bool(predicted.detected[i]) and r.t_r_s is not None:
                errors.append((r.t_r_s - float(predicted.t_r_s[i])) * 1e3)
        out.append(
            ActuatorSummary(
                actuator,
                len(rows),
                sum(r.detected for r in rows),
                float(energies.min()) if hit else None,
                max((float(r.energy_j or 0.0) for r in miss), default=None),
                slope,
                curve.min_detectable_energy_j,
                curve.delta_e_slope,
                float(np.median(errors)) if errors else None,
            )
        )
    return out
