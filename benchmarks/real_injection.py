"""The discrepancy tool on real recordings with known effects concealed in them.

    .venv/bin/python benchmarks/real_injection.py [--draws 5] [--data DIR] [--out DIR]

The recordings are the real T-Motor AK80-6 pendulum runs of ../shared/external/actuator_data
(BSD-3, DFKI RIC Underactuated Lab): energy shaping (20 s at 200 Hz) and gravity compensation
(30 s at 1 kHz, moved by hand: a real input no model sees). Their real noise and whatever the
lab's model leaves out stay in; one effect at a time is concealed by changing what was recorded,
so that the recorded motion is exactly that of the system with the effect under the recorded
torque (J q'' = tau_recorded + effect - the rest = tau_applied - the rest):

* torque_offset c: tau_recorded = tau - c;
* payload_gravity P at phi: tau_recorded = tau + P sin(q + phi);
* cogging A at N cycles per revolution: tau_recorded = tau - A sin(N q + phi);
* parameter_drift of the viscous term by s: tau_recorded = tau + (s - 1) b q' (q' a smoothed
  derivative of the real position);
* sensor_delay d: position and velocity recorded d later than the torque.

A torque saturation cannot be concealed in real data without changing the motion, so it is not
among them. The tool runs blind (the nominal model is the lab's parameter file, as a user would
give it); a draw counts as named when the concealed effect is among the findings, and its
parameter error is that of the effect's main parameter. Writes results/real_injection.md.
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from _results import write_results

from transparency_ros.analysis.discrepancy.discover import discover
from transparency_ros.analysis.discrepancy.model import (
    NominalModel,
    Trial,
    load_nominal,
    smooth_derivatives,
)

DATA = Path(__file__).resolve().parents[2] / "shared/external/actuator_data/simple_pendulum_ak80_6"
RECORDINGS = {
    "energy shaping (200 Hz)": ("energy_shaping_data_measured.csv", "sp_parameters_energy.yaml"),
    "gravity compensation (1 kHz, by hand)": (
        "gravity_compensation_data_measured.csv",
        "sp_parameters_gravity.yaml",
    ),
}
EFFECTS = ("torque_offset", "payload_gravity", "cogging", "parameter_drift", "sensor_delay")
MAIN = {
    "torque_offset": "offset_nm",
    "payload_gravity": "mgl_nm",
    "cogging": "amplitude_nm",
    "parameter_drift": "viscous_scale",
    "sensor_delay": "delay_s",
}


@dataclass
class Draw:
    recording: str
    effect: str
    truth: dict[str, float]
    found: list[str]
    value: float | None  # the named effect's main parameter
    error: float | None  # relative error of it
    seconds: float


def load(csv: Path) -> Trial:
    t, q, qd, tau = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    return Trial(csv.stem, t - t[0], q, qd, tau)


def draw_truth(effect: str, rng: random.Random, tau: np.ndarray) -> dict[str, float]:
    scale = float(np.percentile(np.abs(tau), 90))  # the recording's torques
    if effect == "torque_offset":
        return {"offset_nm": rng.choice((-1, 1)) * rng.uniform(0.1, 0.25) * scale}
    if effect == "payload_gravity":
        return {"mgl_nm": rng.uniform(0.15, 0.4) * scale, "offset_rad": rng.uniform(-0.5, 0.5)}
    if effect == "cogging":
        return {
            "amplitude_nm": rng.uniform(0.1, 0.2) * scale,
            "cycles_per_rev": float(rng.randint(6, 24)),
            "phase_rad": rng.uniform(-math.pi, math.pi),
        }
    if effect == "parameter_drift":
        return {"viscous_scale": rng.choice((rng.uniform(0.3, 0.6), rng.uniform(1.8, 3.0)))}
    return {"delay_s": rng.uniform(0.008, 0.02)}


def conceal(trial: Trial, model: NominalModel, effect: str, p: dict[str, float]) -> Trial:
    t, q, qd, tau = trial.t, trial.q, trial.qd, trial.tau
    if effect == "torque_offset":
        tau = tau - p["offset_nm"]
    elif effect == "payload_gravity":
        tau = tau + p["mgl_nm"] * np.sin(q + p["offset_rad"])
    elif effect == "cogging":
        tau = tau - p["amplitude_nm"] * np.sin(p["cycles_per_rev"] * q + p["phase_rad"])
    elif effect == "parameter_drift":
        velocity, _ = smooth_derivatives(trial, 0.02, 2)
        tau = tau + (p["viscous_scale"] - 1.0) * model.viscous_nms_per_rad * velocity
    else:  # the position answers the torque d later: recorded position at t is q(t - d)
        keep = t >= t[0] + p["delay_s"]
        shifted = t[keep] - p["delay_s"]
        q, qd = np.interp(shifted, t, q), np.interp(shifted, t, qd)
        t, tau = t[keep], tau[keep]
    return Trial(f"{trial.name}+{effect}", t, q, qd, tau)


def run_draw(recording: str, effect: str, seed: int, data: Path) -> Draw:
    csv, spec = RECORDINGS[recording]
    trial = load(data / csv)
    model = load_nominal(data / spec)
    truth = draw_truth(effect, random.Random(seed), trial.tau)
    started = time.perf_counter()
    report = discover(model, [conceal(trial, model, effect, truth)])
    found = [f.effect for f in report.findings]
    value = error = None
    for f in report.findings:
        if f.effect == effect:
            value = f.parameters[MAIN[effect]]
            reference = truth[MAIN[effect]]
            if effect == "parameter_drift":  # the drift of the term, not of its scale
                error = abs(value - reference) / abs(reference - 1.0)
            else:
                error = abs(value - reference) / abs(reference)
    return Draw(recording, effect, truth, found, value, error, time.perf_counter() - started)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--draws", type=int, default=5, help="draws per effect and recording")
    parser.add_argument("--data", default=str(DATA), help="the actuator_data folder")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    data = Path(args.data)
    started = time.perf_counter()
    draws: list[Draw] = []
    baseline: dict[str, Any] = {}
    for recording, (csv, spec) in RECORDINGS.items():
        report = discover(load_nominal(data / spec), [load(data / csv)])
        baseline[recording] = {
            "findings": [f.effect for f in report.findings],
            "heldout_rmse": report.final_heldout_rmse,
        }
        for effect in EFFECTS:
            for k in range(args.draws):
                d = run_draw(recording, effect, 1000 + k, data)
                draws.append(d)
                named = "named" if effect in d.found else "missed"
                err = f"{d.error:.0%}" if d.error is not None else "-"
                print(f"{recording} {effect} {k}: {named} {d.found} error {err} "
                      f"({d.seconds:.1f} s)", file=sys.stderr)  # fmt: skip
    lines = [
        "Real AK80-6 pendulum recordings with one concealed effect each "
        f"({args.draws} draws per effect and recording), the tool blind",
        "",
        "| recording | effect | named | other names | parameter error median / max |",
        "|---|---|---|---|---|",
    ]
    for recording in RECORDINGS:
        for effect in EFFECTS:
            rows = [d for d in draws if d.recording == recording and d.effect == effect]
            named = [d for d in rows if d.error is not None]
            others = sorted({n for d in rows for n in d.found if n != effect})
            errors = [d.error for d in named if d.error is not None]
            spread = f"{np.median(errors):.0%} / {max(errors):.0%}" if errors else "-"
            lines.append(
                f"| {recording} | {effect} | {len(named)}/{len(rows)} | "
                f"{', '.join(others) or '-'} | {spread} |"
            )
    named = [d for d in draws if d.error is not None]
    errors = [d.error for d in named if d.error is not None]
    extra = sum(len([n for n in d.found if n != d.effect]) for d in draws)
    lines += [
        "",
        f"In all: {len(named)}/{len(draws)} named ({len(named) / len(draws):.0%}); parameter "
        f"error median {np.median(errors):.0%}, max {max(errors):.0%}; {extra} other names "
        "next to them. Without a concealed effect: "
        + "; ".join(f"{r}: {b['findings'] or 'nothing named'}" for r, b in baseline.items())
        + f". {time.perf_counter() - started:.0f} s "
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
