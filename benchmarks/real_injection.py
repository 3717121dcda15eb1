"""The discrepancy tool on real recordings with known effects concealed in them, at sizes
measured against what the nominal model already misses on each recording.

    .venv/bin/python benchmarks/real_injection.py [--draws 3] [--ratios 0.5 1 2 4] [--jobs 2]

The recordings are real and were made by others: the T-Motor AK80-6 pendulum runs of
../shared/external/actuator_data (BSD-3, DFKI RIC Underactuated Lab), energy shaping (20 s at
200 Hz) and gravity compensation (30 s at 1 kHz, moved by hand: a real input no model sees), and
the elbow of the lab's real double pendulum (../shared/external/double_pendulum, the 10 runs
without disturbances, about 400 Hz with dropped samples), a 1-DoF joint whose coupling to the
shoulder (the lab's equations, the shoulder's recorded motion) is a known input. Their real
noise and whatever the lab's model leaves out stay in; one effect at a time is concealed by
changing what was recorded, so that the recorded motion is exactly that of the system with the
effect under the recorded torque (J q'' = tau_recorded + effect - the rest = tau_applied - the
rest):

* torque_offset c: tau_recorded = tau - c;
* payload_gravity P at phi: tau_recorded = tau + P sin(q + phi);
* cogging A at N cycles per revolution: tau_recorded = tau - A sin(N q + phi);
* parameter_drift of a friction term by s: tau_recorded = tau + (s - 1) F(q'), F the nominal
  viscous or Coulomb term, whichever is larger at the recording's median speed (q' a smoothed
  derivative of the real position);
* sensor_delay of k whole samples: the position recorded k samples after the torque that moved
  it (whole samples, so that the real encoder noise is kept, not smoothed by interpolation).

**Sizes.** An effect's size is set by what it does to the nominal model's 0.1 s predictions:
its *signature* is the RMS change of those predictions when the recording is concealed, and
the recording's *own error* is the nominal model's RMS prediction error on the untouched
recording (real unmodelled dynamics and noise). A draw's shape (sign, phase, period) is random;
its amplitude is then scaled so that signature = ratio x own error (the whole-sample delay: the
smallest delay that reaches it). At ratio 1 the concealed effect changes the predictions as
much as everything the model already misses on that recording. The figures are given per
ratio, so that what the tool can and cannot see on real data is read off one table.

A torque saturation cannot be concealed in real data without changing the motion, so it is not
among them; nor a payload on the elbow (its gravity pulls with sin(q1 + q2), not a function of
the elbow's own angle). The tool runs blind (the nominal model is the lab's parameter file,
as a user would give it); a draw counts as named when the concealed effect is among the
findings, and its parameter error is that of the effect's main parameter against the concealed
value alone (the recording's own share of the same effect, e.g. a real torque offset of its
own, counts as error). Every concealed value stays within 90 % of the range the tool searches
(offsets and cogging up to 4.5 N m, a friction term x0.1 to x4.5, delays up to 45 ms: beyond,
the tool cannot name it by design); where that is below the size asked for, the table gives
the size reached. The summary also counts the draws whose effect reaches at least x1 there:
an effect that cannot move the predictions as much as the model already misses them, within
the range the tool searches (a 45 ms delay on slow torques: x0.1), is not one the recording
shows. Writes results/real_injection.md and .json.
"""

from __future__ import annotations

import argparse
import lzma
import math
import random
import sys
import time
from dataclasses import dataclass
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).parent))

from _results import write_results

from transparency_ros.analysis.discrepancy.discover import discover
from transparency_ros.analysis.discrepancy.effects import library
from transparency_ros.analysis.discrepancy.model import (
    FloatArray,
    NominalModel,
    Trial,
    load_nominal,
    make_windows,
    smooth_derivatives,
)
from transparency_ros.analysis.discrepancy.torque_driven import TorqueDrivenProblem, predict

SHARED = Path(__file__).resolve().parents[2] / "shared/external"
PENDULUM = "actuator_data/simple_pendulum_ak80_6"
PENDUBOT = "double_pendulum"
EFFECTS = ("torque_offset", "payload_gravity", "cogging", "parameter_drift", "sensor_delay")
MAIN = {
    "torque_offset": "offset_nm",
    "payload_gravity": "mgl_nm",
    "cogging": "amplitude_nm",
    "parameter_drift": "friction_scale",  # reported as the scale of the drifted term
    "sensor_delay": "delay_s",
}


def load_csv(csv: Path) -> Trial:
    t, q, qd, tau = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    return Trial(csv.stem, t - t[0], q, qd, tau)


def load_pendubot_elbow(path: Path, p: dict[str, float]) -> Trial:
    """The elbow of the real double pendulum as a 1-DoF torque-driven joint, the shoulder's
    coupling a known input. From the lab's equations (README of the data), the elbow's row:
    M11 q2'' = tau2 - M10(q2) q1'' - m2 l1 r2 sin(q2) q1'^2 - m2 g r2 sin(q1 + q2) - F2(q2'),
    M11 = I2 + gr^2 Ir, M10 = I2 + m2 l1 r2 cos q2 - gr Ir; q1', q1'' a Savitzky-Golay
    derivative (30 ms) of the shoulder's recorded position; tau2 the controller's elbow
    command (pendubot: the elbow only compensates its friction)."""
    with lzma.open(path, "rt") as f:
        d = np.genfromtxt(f, delimiter=",", names=True)
    t, q1, q2 = d["time"] - d["time"][0], d["pos_meas1"], d["pos_meas2"]
    v1, a1 = smooth_derivatives(Trial("shoulder", t, q1, d["vel_meas1"], d["tau_meas1"]), 0.03, 3)
    m2, l1, r2 = p["m2"], p["l1"], p["r2"]
    m10 = p["I2"] + m2 * l1 * r2 * np.cos(q2) - p["gr"] * p["Ir"]
    coupling = m10 * a1 + m2 * l1 * r2 * np.sin(q2) * v1**2 + m2 * p["g"] * r2 * np.sin(q1 + q2)
    return Trial(path.name.split(".")[0], t, q2, d["vel_meas2"], d["tau_con2"] - coupling)


def load_recording(name: str, shared: Path) -> tuple[NominalModel, list[Trial]]:
    """(the nominal model a user would give, the trials) of one of ``RECORDINGS``."""
    if name.startswith("pendubot"):
        folder = shared / PENDUBOT
        p = yaml.safe_load((folder / "model_parameters.yml").read_text())
        model = NominalModel(  # the lab's F = b q' + cf atan(100 q'): Coulomb cf pi/2
            inertia_kgm2=p["I2"] + p["gr"] ** 2 * p["Ir"],
            viscous_nms_per_rad=p["b2"],
            coulomb_nm=p["cf2"] * math.pi / 2,
            coulomb_smoothing_rad_s=math.pi / 2 / 100,
        )
        runs = sorted(folder.glob("pendubot_clean_*.csv.xz"))
        return model, [load_pendubot_elbow(r, p) for r in runs]
    csv, spec = RECORDINGS[name]
    return load_nominal(shared / PENDULUM / spec), [load_csv(shared / PENDULUM / csv)]


RECORDINGS = {
    "energy shaping (200 Hz)": ("energy_shaping_data_measured.csv", "sp_parameters_energy.yaml"),
    "gravity compensation (1 kHz, by hand)": (
        "gravity_compensation_data_measured.csv",
        "sp_parameters_gravity.yaml",
    ),
    "pendubot elbow (10 runs, 400 Hz)": ("", ""),
}
# a payload on the elbow pulls with sin(q1 + q2), which no 1-DoF effect of q2 can be
SKIP = {("pendubot elbow (10 runs, 400 Hz)", "payload_gravity")}


@dataclass
class Draw:
    recording: str
    effect: str
    ratio: float  # the signature asked for, as a multiple of the recording's own error
    achieved: float  # the signature concealed (a whole-sample delay rarely hits it exactly)
    truth: dict[str, float]
    found: list[str]
    value: float | None  # the named effect's main parameter
    error: float | None  # relative error of it
    seconds: float


def draw_shape(effect: str, rng: random.Random) -> dict[str, float]:
    """The random part of a draw, its amplitude 1 (scaled afterwards to the asked size)."""
    if effect == "torque_offset":
        return {"offset_nm": float(rng.choice((-1, 1)))}
    if effect == "payload_gravity":
        return {"mgl_nm": 1.0, "offset_rad": rng.uniform(-math.pi, math.pi)}
    if effect == "cogging":
        return {
            "amplitude_nm": 1.0,
            "cycles_per_rev": float(rng.randint(6, 24)),
            "phase_rad": rng.uniform(-math.pi, math.pi),
        }
    if effect == "parameter_drift":
        return {"friction_scale": float(rng.choice((-1, 1)))}  # the sign of s - 1
    return {"delay_s": 1.0}


def drifted_term(model: NominalModel, trials: list[Trial]) -> str:
    """The nominal friction term a drift changes: the larger at the recordings' median speed
    (the gravity-compensation run's viscous term is 0.1 N m at 1 rad/s, its Coulomb 1.3)."""
    speed = float(np.median(np.abs(np.concatenate([tr.qd for tr in trials]))))
    viscous = model.viscous_nms_per_rad * speed
    return "viscous_scale" if viscous >= model.coulomb_nm else "coulomb_scale"


def scaled(effect: str, shape: dict[str, float], amplitude: float, dt: float) -> dict[str, float]:
    p = dict(shape)
    if effect == "parameter_drift":
        p["friction_scale"] = 1.0 + shape["friction_scale"] * amplitude
    elif effect == "sensor_delay":
        p["delay_s"] = round(amplitude) * dt
    else:
        p[MAIN[effect]] = shape[MAIN[effect]] * amplitude
    return p


def conceal(
    trial: Trial, model: NominalModel, effect: str, p: dict[str, float], term: str
) -> tuple[Trial, Trial]:
    """(the untouched recording, the recording with ``effect`` concealed), sample for sample
    (a delay drops the last k samples of both)."""
    t, q, qd, tau = trial.t, trial.q, trial.qd, trial.tau
    if effect == "torque_offset":
        tau = tau - p["offset_nm"]
    elif effect == "payload_gravity":
        tau = tau + p["mgl_nm"] * np.sin(q + p["offset_rad"])
    elif effect == "cogging":
        tau = tau - p["amplitude_nm"] * np.sin(p["cycles_per_rev"] * q + p["phase_rad"])
    elif effect == "parameter_drift":
        v, _ = smooth_derivatives(trial, 0.02, 2)
        friction = (
            model.viscous_nms_per_rad * v
            if term == "viscous_scale"
            else model.coulomb_nm * np.tanh(v / model.coulomb_smoothing_rad_s)
        )
        tau = tau + (p["friction_scale"] - 1.0) * friction
    else:  # the position recorded k samples after the torque that moved it
        k = round(p["delay_s"] / trial.dt)
        if k > 0:
            keep = slice(None, t.size - k)
            original = Trial(trial.name, t[keep], q[keep], qd[keep], tau[keep])
            return original, Trial(f"{trial.name}+{effect}", t[keep], q[keep], qd[keep], tau[k:])
    return trial, Trial(f"{trial.name}+{effect}", t, q, qd, tau)


def predictions(model: NominalModel, trials: list[Trial]) -> tuple[FloatArray, FloatArray]:
    """The nominal model's 0.1 s predictions of every window of ``trials`` (as the tool makes
    them) and the recorded positions."""
    w = make_windows(trials, 0.1, stride_s=0.1)
    return predict(model, [], [], w), w.q


def signature(model: NominalModel, original: list[Trial], concealed: list[Trial]) -> float:
    before, _ = predictions(model, original)
    after, _ = predictions(model, concealed)
    return float(np.sqrt(np.mean((after - before) ** 2)))


def own_error(model: NominalModel, trials: list[Trial]) -> float:
    predicted, recorded = predictions(model, trials)
    return float(np.sqrt(np.mean((predicted - recorded) ** 2)))


def conceal_all(
    trials: list[Trial], model: NominalModel, effect: str, p: dict[str, float], term: str
) -> tuple[list[Trial], list[Trial]]:
    pairs = [conceal(tr, model, effect, p, term) for tr in trials]
    return [a for a, _ in pairs], [b for _, b in pairs]


def largest(effect: str, shape: dict[str, float], dt: float) -> float:
    """The largest amplitude whose value stays within 90 % of the range the tool searches (a
    value the tool cannot reach, or fits at its bound, cannot be named)."""
    tool = {e.name: e for e in library()}[effect]
    if effect == "sensor_delay":
        return float(math.floor(0.9 * tool.upper[0] / dt))
    if effect == "parameter_drift":  # the friction scales: 0 .. 5
        return 0.9 if shape["friction_scale"] < 0 else 0.9 * tool.upper[1] - 1.0
    return 0.9 * tool.upper[tool.param_names.index(MAIN[effect])]


def size_draw(
    trials: list[Trial],
    model: NominalModel,
    effect: str,
    shape: dict[str, float],
    target: float,
    *,
    term: str,
) -> tuple[dict[str, float], float]:
    """The draw's parameters at the amplitude whose signature is ``target`` (bisection; the
    delay: the smallest whole-sample delay that reaches it), at most :func:`largest`, and the
    signature reached."""
    dt = trials[0].dt
    most = largest(effect, shape, dt)

    def sig(amplitude: float) -> float:
        p = scaled(effect, shape, amplitude, dt)
        return signature(model, *conceal_all(trials, model, effect, p, term))

    if effect == "sensor_delay":
        k = 1
        while k < most and sig(k) < target:
            k += 1
        return scaled(effect, shape, k, dt), sig(k)
    if sig(most) < target:  # out of the tool's range before it reaches the size
        return scaled(effect, shape, most, dt), sig(most)
    low, high = 0.0, most
    for _ in range(30):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if sig(mid) < target else (low, mid)
    return scaled(effect, shape, high, dt), sig(high)


def run_draw(job: tuple[str, str, float, int, str]) -> Draw:
    recording, effect, ratio, seed, shared = job
    model, trials = load_recording(recording, Path(shared))
    term = drifted_term(model, trials)
    own = own_error(model, trials)
    shape = draw_shape(effect, random.Random(seed))
    truth, reached = size_draw(trials, model, effect, shape, ratio * own, term=term)
    started = time.perf_counter()
    _, concealed = conceal_all(trials, model, effect, truth, term)
    report = discover(model, concealed)
    found = [f.effect for f in report.findings]
    value = error = None
    for f in report.findings:
        if f.effect == effect:
            if effect == "parameter_drift":  # the drift of the term, not of its scale
                value = f.parameters[term]
                error = abs(value - truth["friction_scale"]) / abs(truth["friction_scale"] - 1)
            else:
                value = f.parameters[MAIN[effect]]
                error = abs(value - truth[MAIN[effect]]) / abs(truth[MAIN[effect]])
    if effect == "parameter_drift":
        truth = {**truth, "term_is_coulomb": float(term == "coulomb_scale")}
    return Draw(
        recording, effect, ratio, reached / own, truth, found, value, error,
        time.perf_counter() - started,
    )  # fmt: skip


def _cell(rows: list[Draw]) -> str:
    named = [d for d in rows if d.error is not None]
    errors = [d.error for d in named if d.error is not None]
    spread = f" ({np.median(errors):.0%})" if errors else ""
    reached = float(np.median([d.achieved for d in rows])) if rows else 0.0
    short = f" at x{reached:.2g}" if rows and reached < 0.95 * rows[0].ratio else ""
    return f"{len(named)}/{len(rows)}{spread}{short}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--draws", type=int, default=3, help="draws per effect, size, recording")
    parser.add_argument(
        "--ratios", type=float, nargs="+", default=[0.5, 1.0, 2.0, 4.0],
        help="signatures to conceal, as multiples of the recording's own error",
    )  # fmt: skip
    parser.add_argument("--jobs", type=int, default=2, help="processes")
    parser.add_argument("--shared", default=str(SHARED), help="the shared/external folder")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    started = time.perf_counter()
    baseline: dict[str, Any] = {}
    for recording in RECORDINGS:
        model, trials = load_recording(recording, Path(args.shared))
        report = discover(model, trials)
        baseline[recording] = {
            "findings": [f.effect for f in report.findings],
            "own_error_rad": own_error(model, trials),
            "noise_floor_rad": TorqueDrivenProblem(model, trials).noise_floor(),
        }
    jobs = [
        (recording, effect, ratio, 1000 + k, args.shared)
        for recording in RECORDINGS
        for effect in EFFECTS
        if (recording, effect) not in SKIP
        for ratio in args.ratios
        for k in range(args.draws)
    ]
    draws: list[Draw] = []
    with Pool(args.jobs) as pool:
        for d in pool.imap(run_draw, jobs):
            draws.append(d)
            named = "named" if d.effect in d.found else "missed"
            err = f"{d.error:.0%}" if d.error is not None else "-"
            print(f"{d.recording} {d.effect} x{d.ratio:g} (reached x{d.achieved:.2f}) "
                  f"{d.truth}: {named} {d.found} error {err} ({d.seconds:.1f} s)",
                  file=sys.stderr)  # fmt: skip
    ratios = list(args.ratios)
    lines = [
        "Real AK80-6 recordings (a pendulum; the elbow of a double pendulum) with one concealed "
        "effect each, the tool blind: named "
        f"/ draws ({args.draws} per cell), median parameter error of the named in brackets. "
        "Size = the effect's change of the nominal model's 0.1 s predictions, as a multiple of "
        "the model's own error on the untouched recording.",
        "",
        "| recording | effect | " + " | ".join(f"size x{r:g}" for r in ratios) + " |",
        "|---|---|" + "---|" * len(ratios),
    ]
    for recording in RECORDINGS:
        for effect in EFFECTS:
            if (recording, effect) in SKIP:
                continue
            cells = [
                _cell([d for d in draws if d.recording == recording and d.effect == effect
                       and d.ratio == r])
                for r in ratios
            ]  # fmt: skip
            lines.append(f"| {recording} | {effect} | " + " | ".join(cells) + " |")
    lines.append(
        "| **all** | | "
        + " | ".join(_cell([d for d in draws if d.ratio == r]) for r in ratios)
        + " |"
    )
    lines += [
        "",
        "| size | named | parameter error median / max | other names next to a named one "
        "| named where the effect reaches x1 (median error) |",
        "|---|---|---|---|---|",
    ]
    for r in ratios:
        rows = [d for d in draws if d.ratio == r]
        errors = [d.error for d in rows if d.error is not None]
        spread = f"{np.median(errors):.0%} / {max(errors):.0%}" if errors else "-"
        extra = sum(len([n for n in d.found if n != d.effect]) for d in rows)
        n_named = len(errors)
        # an effect that cannot move the predictions as much as the model already misses them,
        # within the range the tool searches, is not one the recording shows
        shown = [d for d in rows if d.achieved >= 1.0]
        shown_errors = [d.error for d in shown if d.error is not None]
        shown_cell = (
            f"{len(shown_errors)}/{len(shown)} ({len(shown_errors) / len(shown):.0%}"
            + (f", {np.median(shown_errors):.0%}" if shown_errors else "")
            + ")"
            if shown
            else "-"
        )
        lines.append(
            f"| x{r:g} | {n_named}/{len(rows)} ({n_named / len(rows):.0%}) | {spread} | {extra} "
            f"| {shown_cell} |"
        )
    lines += [
        "",
        "The recordings' own error (nominal model, 0.1 s predictions) and what the tool names "
        "on them untouched: "
        + "; ".join(
            f"{r}: {b['own_error_rad'] * 1000:.1f} mrad (noise floor "
            f"{b['noise_floor_rad'] * 1000:.1f}), "
            f"{', '.join(b['findings']) or 'nothing named'}"
            for r, b in baseline.items()
        )
        + f". {args.jobs} processes, {time.perf_counter() - started:.0f} s "
        "(`.venv/bin/python benchmarks/real_injection.py`).",
    ]
    write_results(
        args.out,
        "real_injection",
        lines,
        {"draws": [vars(d) for d in draws], "baseline": baseline},
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
