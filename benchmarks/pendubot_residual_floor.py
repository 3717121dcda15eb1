"""How low can the observer's residual get on the real double pendulum without contact?

    .venv/bin/python benchmarks/pendubot_residual_floor.py [--gain 20] [--shared DIR] [--out DIR]

The detection goal (90 % of the 0.2–0.5 N·m pulses at ≤ 1 false alarm per minute) needs a
residual whose peaks on runs without contact stay below the pulses. This measures those peaks on
the 10 clean runs, leave-one-run-out (calibrate on 9, run the node's pipeline on the held-out
one), for the calibrated detector and for three changes that each remove a suspected source of
error:

* ``position velocity``: the velocity from the positions (central difference, the observer one
  sample behind) instead of the motor-reported one, whose single-sample glitches reach 2 rad/s;
* ``measured torque``: the motor-reported torque in place of the command. On clean runs this
  is the torque the motor applied, so it bounds what any model of the actuator's response
  (delay, saturation) could achieve. It cannot be used for detection: on the disturbed runs it
  contains the pulse;
* ``state kNN``: a nonparametric model of the remaining residual as a function of the state
  (sin/cos of both angles, both velocities; mean of the 20 nearest samples of the 9 calibration
  runs) subtracted from it.

Reported per variant and joint: the held-out runs' residual RMS and peak (median and range over
the 10 runs). The pulses' own size is the bound a detector must beat: a residual peak above it on a
clean run is a false alarm at any threshold that would find that pulse.
Writes benchmarks/results/pendubot_residual_floor.md and .json.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from transparency_ros.analysis import robot_detect as rd
from transparency_ros.analysis.robot_calibration import calibrate, run_pipeline
from transparency_ros.analysis.robot_data import Columns, JointRecording, read_joint_csv
from transparency_ros.core.robot_model import RobotModel

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_results

SHARED = Path(__file__).resolve().parents[2] / "shared" / "external" / "double_pendulum"
NEIGHBOURS = 20


def position_velocity(rec: JointRecording) -> JointRecording:
    """The run one sample behind, with the velocity from the positions (central difference)."""
    t = rec.stamps_ns * 1e-9
    q = rec.position
    v = (q[2:] - q[:-2]) / (t[2:] - t[:-2])[:, None]

    def cut(a: Any) -> Any:
        return None if a is None else a[1:-1]

    return replace(
        rec, stamps_ns=rec.stamps_ns[1:-1], position=q[1:-1], velocity=v,
        torque=rec.torque[1:-1], label=cut(rec.label), desired=cut(rec.desired),
    )  # fmt: skip


def state(rec: JointRecording) -> np.ndarray:
    q, v = rec.position, rec.velocity
    return np.column_stack([np.sin(q), np.cos(q), v / 5.0])


def held_out(base: RobotModel, runs: list[JointRecording], gain: float, knn: bool) -> list[Any]:
    """Per held-out run: its residual (samples, joints)."""
    out = []
    for k, held in enumerate(runs):
        train = [r for i, r in enumerate(runs) if i != k]
        cal = calibrate(base, train, gain)
        residual = np.asarray(run_pipeline(base, cal, held)[0])
        if knn:
            x = np.concatenate([state(r) for r in train])
            y = np.concatenate([np.asarray(run_pipeline(base, cal, r)[0]) for r in train])
            ok = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(y), axis=1)
            _, idx = cKDTree(x[ok]).query(state(held), k=NEIGHBOURS)
            residual = residual - y[ok][idx].mean(axis=1)
        out.append(residual)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--gain", type=float, default=20.0)
    parser.add_argument("--shared", default=str(SHARED))
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    started = time.perf_counter()
    root = Path(args.shared)
    base = RobotModel.from_urdf(root / "pendubot.urdf")
    joints = list(base.joint_names)
    files = sorted(root.glob("pendubot_clean_*.csv.xz"))
    command = [read_joint_csv(f, joints) for f in files]
    measured = [read_joint_csv(f, joints, Columns(torque="tau_meas{}")) for f in files]
    pert = [read_joint_csv(f, joints) for f in sorted(root.glob("pendubot_pert_*.csv.xz"))]
    sizes = [p.peak for r in pert for p in rd.pulses(r)]
    variants = {
        "calibrated (the node's)": (command, False),
        "+ position velocity": ([position_velocity(r) for r in command], False),
        "+ position velocity + measured torque": ([position_velocity(r) for r in measured], False),
        "+ position velocity + measured torque + state kNN": (
            [position_velocity(r) for r in measured], True),
        "+ position velocity + state kNN (command)": (
            [position_velocity(r) for r in command], True),
    }  # fmt: skip
    lines = [
        f"Residual of the 10 clean runs of the real double pendulum, leave-one-run-out, "
        f"K_o = {args.gain:g} /s; per joint the held-out runs' RMS and peak [N·m], median "
        f"(min–max) over the runs. The {len(sizes)} pulses of the disturbed runs are "
        f"{min(sizes):.2f}–{max(sizes):.2f} N·m (median {np.median(sizes):.2f}).",
        "",
        "| variant | " + " | ".join(f"{j} RMS | {j} peak" for j in joints) + " |",
        "|---|" + "---|---|" * len(joints),
    ]
    data: dict[str, Any] = {"pulse_sizes_nm": sizes, "variants": {}}
    for name, (runs, knn) in variants.items():
        residuals = held_out(base, runs, args.gain, knn)
        rms = np.array([np.sqrt(np.nanmean(r**2, axis=0)) for r in residuals])
        peak = np.array([np.nanmax(np.abs(r), axis=0) for r in residuals])
        cells = [
            f"{np.median(a[:, j]):.2f} ({a[:, j].min():.2f}–{a[:, j].max():.2f})"
            for j in range(len(joints))
            for a in (rms, peak)
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
        data["variants"][name] = {"rms": rms.tolist(), "peak": peak.tolist()}
        print(f"{name} done ({time.perf_counter() - started:.0f} s)", file=sys.stderr)
    lines += [
        "",
        f"{time.perf_counter() - started:.0f} s (`.venv/bin/python "
        "benchmarks/pendubot_residual_floor.py`).",
    ]
    write_results(args.out, "pendubot_residual_floor", lines, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
