"""What the loop reports: a named effect (:class:`Finding`) with its parameters, intervals, where
it acted and the evidence; the whole :class:`Report`; and what is left ``unexplained``, with
where it sits and what it looks like."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from itertools import product
from typing import Any

import numpy as np

from transparency_ros.analysis.discrepancy.fitting import interval
from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.analysis.discrepancy.problem import Problem, hook

STATE_EXPLAINED = 0.3  # below: the leftover torque is not a function of the state
LEFTOVER = 3.0  # a phase whose residual is above 3x the noise floor is left unexplained
MIN_PHASE = 50  # held-out elements a phase needs to be judged so


@dataclass(frozen=True)
class Finding:
    effect: str
    parameters: dict[str, float]
    confidence_interval: dict[str, tuple[float, float]]
    where: dict[str, Any]
    evidence: str
    heldout_rmse_before: float
    heldout_rmse_after: float
    alternatives: list[str] = field(default_factory=list)  # explain the data as well
    # the recording's channel it was judged on: "simulation" (the simulated positions) or a
    # problem's second one (a drop test's "load cell in the ride", drop_force)
    channel: str = "simulation"
    # each alternative with its fitted values: {effect, parameters, heldout_rmse_ratio (its
    # held-out RMSE over this finding's), told_apart_by (what would tell the two apart,
    # where the recordings say why they cannot; null otherwise)}
    alike: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class Report:
    nominal: dict[str, float]
    split: dict[str, list[str]]
    findings: list[Finding] = field(default_factory=list)
    unexplained: list[dict[str, Any]] = field(default_factory=list)
    heldout_rmse_nominal: float = math.nan
    final_heldout_rmse: float = math.nan
    seconds: float = 0.0
    fitted: list[tuple[Any, FloatArray]] = field(default_factory=list)  # effects as found
    notes: list[str] = field(default_factory=list)  # what was assumed or detected about the data

    def as_dict(self) -> dict[str, Any]:
        return {
            "notes": self.notes,
            "findings": [vars(f) for f in self.findings],
            "unexplained": self.unexplained,
            "nominal": self.nominal,
            "split": self.split,
            "heldout_rmse_nominal": self.heldout_rmse_nominal,
            "final_heldout_rmse": self.final_heldout_rmse,
            "seconds": self.seconds,
        }


def parameters_text(finding: Finding) -> str:
    """A finding's values, each with its 95 % interval where it has one: 'delay_s 0.002
    (95 % 0.0017 to 0.0023)'."""
    parts = []
    for name, value in finding.parameters.items():
        lo, hi = finding.confidence_interval.get(name, (value, value))
        spread = f" (95 % {lo:.3g} to {hi:.3g})" if lo < hi else ""
        parts.append(f"{name} {value:.4g}{spread}")
    return ", ".join(parts)


def locate(
    problem: Problem, before: FloatArray, after: FloatArray, unit: str = "rad"
) -> dict[str, Any]:
    """Where an effect acted: the motion phase whose held-out error it reduced most (the
    reduction in every phase, in ``unit``: the problem's), and the trial and time window of the
    largest reduction."""
    gains = {}
    for name, mask in problem.phases().items():
        if mask.any():
            gains[name] = float(
                np.sqrt(np.mean(before[mask] ** 2)) - np.sqrt(np.mean(after[mask] ** 2))
            )
    phase = max(gains, key=lambda k: gains[k]) if gains else "all"
    segment, labels = problem.segments()
    count = np.bincount(segment, minlength=len(labels)).clip(1)
    per_segment = np.sqrt(np.bincount(segment, before**2, len(labels)) / count) - np.sqrt(
        np.bincount(segment, after**2, len(labels)) / count
    )
    trial, t0, t1 = labels[int(np.argmax(per_segment))]
    return {
        "phase": phase,
        "rmse_reduction_by_phase": gains,
        "unit": unit,
        "trial": trial,
        "window_s": [round(t0, 4), round(t1, 4)],
    }


def alike_fits(problem: Any, step: Any) -> list[dict[str, Any]]:
    """The steps that explained the held-out data alike with ``step`` (``Step.alike``), each
    with its fitted values, its held-out RMSE over the step's, and what would tell it from the
    step where the problem knows why the recordings cannot (``told_apart`` of the problem,
    e.g. an arm that turned one way in every trial: a Coulomb torque and an offset then act
    alike). A user shown two explanations needs both sizes to judge which is plausible."""
    told = hook(problem, "told_apart")
    out = []
    for other in getattr(step, "alike", []):
        values: dict[str, float] = {}
        for effect, x in other.new():
            own = {n: float(v) for n, v in zip(effect.param_names, x, strict=True)}
            own |= effect.extra_parameters(x)
            prefix = f"{effect.name}." if len(other.added) > 1 else ""
            values |= {prefix + n: v for n, v in own.items()}
        out.append(
            {
                "effect": "+".join(a.name for a in other.added),
                "parameters": values,
                "heldout_rmse_ratio": float(other.rmse / step.rmse) if step.rmse > 0 else 1.0,
                "told_apart_by": told(step.added, other.added) or None,
            }
        )
    return out


def alike_text(alike: Sequence[dict[str, Any]], names: Sequence[str]) -> str:
    """'; explained alike by parameter_drift (coulomb_scale 0.626; held-out RMSE 1.000 times
    this): ...' for the evidence (``names``, the alternatives, where no fits are known)."""
    if not alike:
        return f"; explained alike by {', '.join(names)}" if names else ""
    parts = []
    for a in alike:
        values = ", ".join(f"{n} {v:.4g}" for n, v in a["parameters"].items())
        text = f"{a['effect']} ({values}; held-out RMSE {a['heldout_rmse_ratio']:.3f} times this)"
        if a["told_apart_by"]:
            text += f": {a['told_apart_by']}"
        parts.append(text)
    return "; explained alike by " + "; ".join(parts)


def finding(
    problem: Any, cand: Any, step: Any, base: Any, *, before: float, after: float
) -> Finding:
    """What the loop reports of ``cand`` named in ``step`` from ``base``: its parameters and
    intervals, where it acted, and the evidence (held-out RMSE ``before`` -> ``after``)."""
    x = step.params[len(step.params) - len(step.added) + step.added.index(cand)]
    if hasattr(cand, "measured_interval"):  # read off the recording
        ci = cand.measured_interval()
    elif not getattr(cand, "fittable", True) or step.joint:
        # declared (a point), or set from the joint fit afterwards
        ci = [(float(v), float(v)) for v in x]
    else:
        ci = interval(step.result, x)
    together = [a.name for a in step.added if a is not cand]
    judged_on = hook(problem, "channel")
    unit = hook(problem, "unit")
    read_off = hasattr(cand, "describe")
    judged_before, judged_after, judged_floor = step.judged
    judged = (
        f"; judged on the encoder: {judged_before:.4g} -> {judged_after:.4g} rad "
        f"(its floor {judged_floor:.3g} rad)"
        if judged_floor != base.floor
        else ""
    )
    alike = alike_fits(problem, step)
    return Finding(
        effect=cand.name,
        parameters={n: float(v) for n, v in zip(cand.param_names, x, strict=True)}
        | cand.extra_parameters(x),
        confidence_interval={n: c for n, c in zip(cand.param_names, ci, strict=True)},
        where=locate(problem, base.err, step.err, unit),
        evidence=(
            f"held-out {judged_on} RMSE {before:.4g} -> {after:.4g} {unit} "
            f"({abs(100 * (1 - after / before)):.0f} % {'lower' if after <= before else 'higher'})"
            f" with {x.size} parameter(s)"
            + (f"; read off the recording: {cand.describe()}" if read_off else "")
            + judged
            + (f"; {step.elsewhere}" if getattr(step, "elsewhere", "") else "")
            + (
                f"; found together with {', '.join(together)} (neither explains it alone)"
                if together
                else ""
            )
            + alike_text(alike, step.alternatives)
        ),
        heldout_rmse_before=before,
        heldout_rmse_after=after,
        alternatives=list(step.alternatives),
        channel=judged_on,
        alike=alike,
    )


def update_findings(
    report: Report,
    effects: Sequence[Any],
    params: Sequence[FloatArray],
    intervals: Sequence[tuple[float, float]],
) -> None:
    """Parameters and intervals of the findings from a joint refit (intervals in the order
    of the fittable effects' parameters)."""
    k = 0
    for i, (effect, p) in enumerate(zip(effects, params, strict=True)):
        ci = report.findings[i].confidence_interval
        if effect.fittable:
            ci = dict(zip(effect.param_names, intervals[k : k + p.size], strict=True))
            k += p.size
        report.findings[i] = replace(
            report.findings[i],
            parameters={n: float(v) for n, v in zip(effect.param_names, p, strict=True)}
            | effect.extra_parameters(p),
            confidence_interval=ci,
        )


def widen(report: Report, share: float) -> None:
    """Each finding's intervals widened by the model's own error: a half-width of
    sqrt(h^2 + (share x)^2) for a fitted x of statistical half-width h. The fit's interval
    says what the noise allows; what the model still misses (a friction or contact law not
    its own) biases every trial alike, which no interval from the same fit can show. A
    parameter fitted as a logarithm (``log10_...``) is widened by the same share of its
    natural value: log10(1 + share) in the log. Then the intervals of the values derived
    from the fitted ones (``extra_parameters``: a stiffness and its frequency) follow from
    the fitted ones' intervals, as the extremes over their corners."""
    for i, (finding, (effect, p)) in enumerate(zip(report.findings, report.fitted, strict=True)):
        ci = {}
        for name, (lo, hi) in finding.confidence_interval.items():
            x = finding.parameters[name]
            if lo == hi or share <= 0 or not effect.fittable:  # declared or read off
                ci[name] = (lo, hi)
                continue
            model = math.log10(1 + share) if name.startswith("log10_") else share * x
            half = math.hypot((hi - lo) / 2, model)
            ci[name] = (x - half, x + half)
        ci |= derived_intervals(effect, p, ci)
        report.findings[i] = replace(finding, confidence_interval=ci)


def derived_intervals(
    effect: Any, p: FloatArray, ci: dict[str, tuple[float, float]]
) -> dict[str, tuple[float, float]]:
    """The intervals of an effect's derived values (``extra_parameters``): their extremes
    over the corners of the fitted parameters' intervals, exact for values monotonic in each
    parameter (a stiffness from its logarithm, a frequency from the stiffness)."""
    names = list(effect.param_names)
    if not names or any(n not in ci for n in names):
        return {}
    corners = [effect.extra_parameters(np.array(x)) for x in product(*(ci[n] for n in names))]
    out = {}
    for name in effect.extra_parameters(np.asarray(p, dtype=float)):
        values = [c[name] for c in corners if np.isfinite(c.get(name, np.nan))]
        if values and min(values) < max(values):  # (a constant is a choice, not a fit)
            out[name] = (float(min(values)), float(max(values)))
    return out


def unexplained_phases(problem: Problem, err: FloatArray) -> dict[str, float]:
    """The motion phases (``MIN_PHASE`` held-out elements at least) whose residual RMS is above
    ``LEFTOVER`` times the noise floor, with that RMS: what a report leaves unexplained."""
    floor = problem.noise_floor()
    out = {}
    for name, mask in problem.phases().items():
        if mask.sum() < MIN_PHASE:
            continue
        rms = float(np.sqrt(np.mean(err[mask] ** 2)))
        if rms > LEFTOVER * floor:
            out[name] = rms
    return out


def sensor_leftover(problem: Problem, err: FloatArray) -> tuple[str, float, float, str] | None:
    """Where one sensor's part of the held-out error is above ``LEFTOVER`` times that sensor's
    own floor (a problem's ``leftover_scope``: on a drop test the encoder's noise or a count's
    quantization error) while the pooled error is not: (the sensor, its residual RMS, its
    floor, the phase holding most of its squared residual). On zoo_13118 (an offset of
    -0.032 N m hidden, nothing named) the encoder's error was 8x its floor of 0.055 mrad, the
    pooled error at the floor the heights' 1.4 mrad of noise set: the report said nothing was
    left."""
    scope = hook(problem, "leftover_scope")(err)
    if scope is None:
        return None
    mask, floor = scope
    if mask.sum() < MIN_PHASE or floor <= 0:
        return None
    rms = float(np.sqrt(np.mean(err[mask] ** 2)))
    if rms <= LEFTOVER * floor:
        return None
    weight = {name: float(np.sum(err[mask & m] ** 2)) for name, m in problem.phases().items()}
    phase = max(weight, key=weight.__getitem__)
    return str(hook(problem, "scoped_sensor")), rms, floor, phase


def leftover(
    problem: Problem,
    err: FloatArray,
    effects: Sequence[Any] = (),
    params: Sequence[FloatArray] = (),
    closest: tuple[Sequence[str], float] | None = None,
) -> list[dict[str, Any]]:
    """Structure the found effects do not explain: a phase whose residual is well above the
    noise floor, with the frequency where the residual has most power, and the candidate
    that came closest: ``closest`` = (its effects' names: one, or a pair fitted jointly; the
    share it would have removed); where no
    phase is so and one sensor's error is above its own floor (``sensor_leftover``), that."""
    floor = problem.noise_floor()
    found: list[tuple[dict[str, Any], str]] = [
        (
            {"where": {"phase": name}, "rmse_rad": rms, "noise_floor_rad": floor},
            f"residual {rms / floor:.0f}x the noise floor in phase '{name}'"
            if floor > 0
            else f"residual {rms:.2g} rad RMS in phase '{name}' (no noise floor: the "
            "recorded position never changes in the windows compared)",
        )
        for name, rms in unexplained_phases(problem, err).items()
    ]
    own = None if found else sensor_leftover(problem, err)
    if own is not None:
        sensor, rms, own_floor, phase = own
        found.append((
            {"where": {"phase": phase, "sensor": sensor}, "rmse_rad": rms,
             "noise_floor_rad": own_floor},
            f"the {sensor}'s residual {rms / own_floor:.0f}x its own noise floor, most of it "
            f"in phase '{phase}' (pooled with noisier sensors it is within their floor)",
        ))  # fmt: skip
    out = []
    peak: float | None = None
    explained: float | None = None
    for entry, looks in found:
        if peak is None:
            peak = problem.residual_peak_hz(effects, params)
            explained = hook(problem, "state_explained")(effects, params)
        # (the peak is the pooled residual's: not said of one sensor's part of it)
        pooled = "sensor" not in entry["where"]
        entry["dominant_frequency_hz"] = peak if pooled else None
        entry["looks_like"] = looks + (
            f"; the residual peaks near {peak:.1f} Hz" if pooled and not math.isnan(peak) else ""
        )
        if closest is not None and closest[1] > 0:
            names, gain = " + ".join(closest[0]), closest[1]
            entry["closest_candidate"] = {
                "effect": names, "effects": list(closest[0]), "share_removed": gain,
            }  # fmt: skip
            entry["looks_like"] += (
                f"; the closest candidate, {names}, would remove {gain:.0%} of "
                "it, too little to name"
            )
        if explained is not None:
            entry["state_explained_fraction"] = explained
            entry["looks_like"] += (
                f"; position and velocity explain {max(explained, 0.0):.0%} of the "
                "torque residual on held-out trials"
                + (
                    " (not a function of the state: an input the model does not see, "
                    "such as a hand or a contact)"
                    if explained < STATE_EXPLAINED
                    else ""
                )
            )
        out.append(entry)
    return out
