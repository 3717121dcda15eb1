"""A two-link robot written from scratch, to try the robot detector on data it did not shape.

    .venv/bin/python benchmarks/independent_robot.py [--runs 10] [--gain 20] [--out DIR]

Nothing here comes from the package: not its dynamics (no Pinocchio), integrator, friction law,
motor, sensors, controller or file writer. It reads only the DFKI lab's parameter file
(test/data/double_pendulum/model_parameters.yml, a copy of the shared one) and writes CSVs
with the lab's column names, which is all another lab's robot would give this project; the
detector gets the lab's URDF, with its real faults (inertias about the joint axes written as
about the centres of mass, no rotor inertia: the mass matrix about 35 % too large).

The robot: the lab's double pendulum, both joints driven, in the lab's equations of motion
(their README: M(q) q'' + C(q, q') q' - G(q) + F(q') = tau, F_i = b_i q'_i + cf_i atan(100 q'_i)),
integrated with fixed-step RK4 at 0.25 ms, all runs at once. Each motor applies its command
through a first-order lag (1.5 ms), with a torque constant that falls to 0.7 above 4 N m and a
cogging ripple of 0.02 N m; its encoder has 2^14 counts per turn, and the velocity it reports is
the encoder's difference every 0.25 ms low-passed at 250 Hz. The controller runs at 400 Hz (as
the lab's recordings): computed torque with the lab's model plus PD on the reported state,
tracking a sum of two sines per joint (amplitude, frequency and phase drawn per run); tau_con is
its output, the motor gets it clipped at +-10 N m plus the disturbance. Disturbed runs: two
pulses per joint, raised cosines of 0.2-0.5 N m (either sign) lasting 50-100 ms, at least 1 s
apart, as the lab added them (after the controller; tau_pert is their truth).

The survey: 2 folds; each calibrates on half the clean runs, counts false alarms on the other
half and scores every disturbed run; the calibrated detector, the textbook observer (the URDF as
it is, one threshold per joint just above the calibration runs' largest residual) and eq. (1)
(pos_des - pos_meas, thresholds alike), scored as on the real pendubot. Writes
results/independent_robot.md and .json.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

# the lab's files (parameter file, URDF), as kept in this repository with their licence
LAB = Path(__file__).resolve().parents[1] / "test" / "data" / "double_pendulum"
PARAMS = LAB / "model_parameters.yml"
STEP_S = 2.5e-4  # integration step
SUBSTEPS = 10  # per control period: 400 Hz
DURATION_S = 10.0
MOTOR_LAG_S = 1.5e-3
KNEE_NM = 4.0  # above this the torque constant falls to 0.7
COGGING_NM = 0.02
COUNTS = 2**14
VELOCITY_CUTOFF_HZ = 250.0
# the robot is not its identified model: heavier elbow link, its centre of mass further out,
# more friction (the controller and the URDF do not know)
TRUE_CHANGES = {"m2": 1.1, "r2": 1.05, "cf1": 1.3, "cf2": 1.3, "b1": 5.0, "b2": 5.0}
KP = np.array([30.0, 20.0])
KD = np.array([1.2, 0.8])


def lab_parameters() -> dict[str, float]:
    return {k: float(v) for k, v in yaml.safe_load(PARAMS.read_text()).items()}


class Plant:
    """The lab's equations of motion for arrays of runs (q, v: (runs, 2))."""

    def __init__(self, p: dict[str, float]) -> None:
        self.p = p

    def mass(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p = self.p
        c2 = np.cos(q[:, 1])
        ir, gr = p["Ir"], p["gr"]
        m00 = p["I1"] + p["I2"] + p["m2"] * p["l1"] ** 2 + 2 * p["m2"] * p["l1"] * p["r2"] * c2
        m00 = m00 + gr**2 * ir + ir
        m01 = p["I2"] + p["m2"] * p["l1"] * p["r2"] * c2 - gr * ir
        m11 = np.full_like(c2, p["I2"] + gr**2 * ir)
        return m00, m01, m11

    def bias(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """C(q, q') q' - G(q) + F(q'): what the torque must overcome besides inertia."""
        p = self.p
        h = p["m2"] * p["l1"] * p["r2"] * np.sin(q[:, 1])
        coriolis = np.stack([-2 * h * v[:, 0] * v[:, 1] - h * v[:, 1] ** 2, h * v[:, 0] ** 2], 1)
        s1, s12 = np.sin(q[:, 0]), np.sin(q[:, 0] + q[:, 1])
        g0 = -p["m1"] * p["g"] * p["r1"] * s1 - p["m2"] * p["g"] * (p["l1"] * s1 + p["r2"] * s12)
        g1 = -p["m2"] * p["g"] * p["r2"] * s12
        b = np.array([p["b1"], p["b2"]])
        cf = np.array([p["cf1"], p["cf2"]])
        friction = b * v + cf * np.arctan(100 * v)
        return coriolis - np.stack([g0, g1], 1) + friction

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        m00, m01, m11 = self.mass(q)
        rhs = tau - self.bias(q, v)
        det = m00 * m11 - m01 * m01
        return np.stack([(m11 * rhs[:, 0] - m01 * rhs[:, 1]) / det,
                         (m00 * rhs[:, 1] - m01 * rhs[:, 0]) / det], 1)  # fmt: skip

    def inverse(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        m00, m01, m11 = self.mass(q)
        inertial = np.stack([m00 * a[:, 0] + m01 * a[:, 1], m01 * a[:, 0] + m11 * a[:, 1]], 1)
        return inertial + self.bias(q, v)


def motor_torque(current: np.ndarray, q: np.ndarray, gr: float) -> np.ndarray:
    """What the motor applies for the lagged command ``current`` [N m at the joint]."""
    size = np.abs(current)
    applied = np.where(size > KNEE_NM, KNEE_NM + 0.7 * (size - KNEE_NM), size)
    return np.sign(current) * applied + COGGING_NM * np.sin(21 * gr * q)


def references(rng: np.random.Generator, runs: int) -> np.ndarray:
    """Per run and joint two sines: (runs, 2 joints, 2 sines, [amplitude, omega, phase])."""
    amp = rng.uniform(0.4, 0.9, size=(runs, 2, 2)) * np.array([1.0, 0.75])[:, None]
    omega = 2 * math.pi * rng.uniform(0.3, 1.0, size=(runs, 2, 2))
    phase = rng.uniform(0, 2 * math.pi, size=(runs, 2, 2))
    return np.stack([amp, omega, phase], -1)


def desired(ref: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of the reference at ``t``: the sines less their
    start value, faded in over the first second (every run starts at rest, hanging down)."""
    amp, omega, phase = ref[..., 0], ref[..., 1], ref[..., 2]
    angle = omega * t + phase
    s = (amp * (np.sin(angle) - np.sin(phase))).sum(-1)
    ds = (amp * omega * np.cos(angle)).sum(-1)
    dds = (-amp * omega**2 * np.sin(angle)).sum(-1)
    if t >= 1.0:
        return s, ds, dds
    r, dr, ddr = (
        0.5 * (1 - math.cos(math.pi * t)),
        0.5 * math.pi * math.sin(math.pi * t),
        (0.5 * math.pi**2 * math.cos(math.pi * t)),
    )
    return r * s, dr * s + r * ds, ddr * s + 2 * dr * ds + r * dds


def pulses(
    rng: np.random.Generator, runs: int, duration_s: float
) -> list[list[tuple[int, float, float, float]]]:
    """Per run: (joint, start [s], duration [s], amplitude [N m]), 2 per joint, >= 1 s apart."""
    if duration_s < 6.0:
        raise ValueError("disturbed runs need at least 6 s for their four pulses")
    out = []
    for _ in range(runs):
        while True:
            starts = np.sort(rng.uniform(1.5, duration_s - 0.5, size=4))
            if np.all(np.diff(starts) >= 1.1):
                break
        joints = rng.permutation([0, 0, 1, 1])
        out.append([
            (int(j), float(s), float(rng.uniform(0.05, 0.1)),
             float(rng.choice([-1, 1]) * rng.uniform(0.2, 0.5)))
            for j, s in zip(joints, starts, strict=True)
        ])  # fmt: skip
    return out


def disturbance(events: list[list[tuple[int, float, float, float]]], t: float) -> np.ndarray:
    out = np.zeros((len(events), 2))
    for r, run in enumerate(events):
        for joint, start, duration, amp in run:
            if start <= t < start + duration:
                out[r, joint] += amp * 0.5 * (1 - math.cos(2 * math.pi * (t - start) / duration))
    return out


def simulate(
    seed: int, runs: int, disturbed: bool, duration_s: float = DURATION_S
) -> list[dict[str, np.ndarray]]:
    """``runs`` runs drawn from ``seed``; per run its columns (the lab's names)."""
    rng = np.random.default_rng(seed)
    p = lab_parameters()
    model = Plant(p)  # the controller's
    plant = Plant({k: v * TRUE_CHANGES.get(k, 1.0) for k, v in p.items()})
    ref = references(rng, runs)
    events = pulses(rng, runs, duration_s) if disturbed else [[] for _ in range(runs)]
    q, v = np.zeros((runs, 2)), np.zeros((runs, 2))
    current = np.zeros((runs, 2))  # the motors' lagged command
    counts = 2 * math.pi / COUNTS
    encoder = np.zeros((runs, 2))
    v_report = np.zeros((runs, 2))
    alpha = 1 - math.exp(-2 * math.pi * VELOCITY_CUTOFF_HZ * STEP_S)
    samples = round(duration_s / (STEP_S * SUBSTEPS))
    cols: dict[str, list[np.ndarray]] = {k: [] for k in (
        "time", "pos_meas", "vel_meas", "tau_con", "tau_meas", "tau_pert", "pos_des")}  # fmt: skip

    def derivative(state: np.ndarray, command: np.ndarray) -> np.ndarray:
        qs, vs, cs = state[:, 0:2], state[:, 2:4], state[:, 4:6]
        tau = motor_torque(cs, qs, p["gr"])
        return np.concatenate(
            [vs, plant.acceleration(qs, vs, tau), (command - cs) / MOTOR_LAG_S], 1
        )

    for k in range(samples):
        t = k * STEP_S * SUBSTEPS
        q_meas = encoder.copy()
        qd, vd, ad = desired(ref, t)
        tau_con = model.inverse(qd, vd, ad) + KP * (qd - q_meas) + KD * (vd - v_report)
        pert = disturbance(events, t)
        command = np.clip(tau_con, -10.0, 10.0) + pert
        for name, value in (("time", np.full(runs, t)), ("pos_meas", q_meas),
                            ("vel_meas", v_report.copy()), ("tau_con", tau_con),
                            ("tau_meas", motor_torque(current, q, p["gr"])),
                            ("tau_pert", pert), ("pos_des", qd)):  # fmt: skip
            cols[name].append(value)
        for _ in range(SUBSTEPS):
            state = rk4(derivative, np.concatenate([q, v, current], 1), command)
            q, v, current = state[:, 0:2], state[:, 2:4], state[:, 4:6]
            new = np.round(q / counts) * counts
            v_report += alpha * ((new - encoder) / STEP_S - v_report)
            encoder = new
    return per_run(cols, runs)


def rk4(
    derivative: Callable[[np.ndarray, np.ndarray], np.ndarray],
    state: np.ndarray,
    command: np.ndarray,
) -> np.ndarray:
    """One RK4 step of ``STEP_S``, the command held over it."""
    k1 = derivative(state, command)
    k2 = derivative(state + 0.5 * STEP_S * k1, command)
    k3 = derivative(state + 0.5 * STEP_S * k2, command)
    k4 = derivative(state + STEP_S * k3, command)
    return state + STEP_S / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def per_run(cols: dict[str, list[np.ndarray]], runs: int) -> list[dict[str, np.ndarray]]:
    """Columns recorded for all runs at once (per sample, (runs,) or (runs, 2)) as each run's
    columns with the lab's names (``time``, ``pos_meas1``, ``pos_meas2``, ...)."""
    out = []
    for r in range(runs):
        run = {"time": np.array([c[r] for c in cols["time"]])}
        for name, column in cols.items():
            if name == "time":
                continue
            stacked = np.array([c[r] for c in column])
            for j in range(2):
                run[f"{name}{j + 1}"] = stacked[:, j]
        out.append(run)
    return out


def write_csv(path: Path, run: dict[str, np.ndarray]) -> Path:
    names = list(run)
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in zip(*(run[n] for n in names), strict=True):
            writer.writerow([f"{x:.9g}" for x in row])
    return path


def write_runs(
    directory: Path, runs: int, seed: int = 1, duration_s: float = DURATION_S
) -> tuple[list[Path], list[Path]]:
    """``runs`` clean and ``runs`` disturbed CSVs in ``directory`` (clean_NN, pert_NN)."""
    directory.mkdir(parents=True, exist_ok=True)
    clean = [write_csv(directory / f"clean_{k:02d}.csv", r)
             for k, r in enumerate(simulate(seed, runs, False, duration_s))]  # fmt: skip
    pert = [write_csv(directory / f"pert_{k:02d}.csv", r)
            for k, r in enumerate(simulate(seed + 1000, runs, True, duration_s))]  # fmt: skip
    return clean, pert


# ---------------------------------------------------------------------- the survey (the package)


def survey(directory: Path, runs: int, gain: float) -> dict[str, Any]:
    sys.path.insert(0, str(Path(__file__).parent))
    from pendubot_residual_floor import position_velocity  # noqa: PLC0415

    from transparency_ros.analysis.robot_data import read_joint_csv  # noqa: PLC0415
    from transparency_ros.core.robot_model import RobotModel  # noqa: PLC0415

    base = RobotModel.from_urdf(LAB / "pendubot.urdf")
    joints = list(base.joint_names)
    clean_files, pert_files = write_runs(directory, runs)
    clean = [read_joint_csv(f, joints) for f in clean_files]
    pert = [read_joint_csv(f, joints) for f in pert_files]
    out: dict[str, Any] = {"joints": joints, "runs": runs, "gain": gain, "methods": {}}
    out["methods"].update(_methods(base, clean, pert, gain))
    # the same with the velocity from the positions (central difference, a sample behind)
    # in place of the motors' reported one, whose noise enters the residual as K_o M(q) dv
    smooth = [position_velocity(r) for r in clean], [position_velocity(r) for r in pert]
    observers = ("calibrated", "textbook")
    suffix = ", velocity from positions"
    out["methods"].update(_methods(base, *smooth, gain, suffix=suffix, methods=observers))
    return out


def _methods(
    base: Any, clean: list[Any], pert: list[Any], gain: float, *, suffix: str = "",
    methods: tuple[str, ...] = ("calibrated", "textbook", "position_error"),
) -> dict[str, Any]:  # fmt: skip
    """Per detector: pooled scores per joint on the disturbed and held-out clean runs, and the
    held-out clean runs' residual (RMS, peak) per joint."""
    from transparency_ros.analysis import robot_detect as rd  # noqa: PLC0415
    from transparency_ros.analysis.robot_calibration import calibrate  # noqa: PLC0415

    joints = list(base.joint_names)
    runs = len(clean)
    half = runs // 2
    folds = [(clean[:half], clean[half:]), (clean[half:], clean[:half])]
    scores: dict[str, dict[str, list[Any]]] = {m: {"held_clean": [], "pert": []} for m in methods}
    floor: dict[str, list[Any]] = {m: [] for m in methods}
    for train, held in folds:
        cal = calibrate(base, train, gain)
        signals = {
            "textbook": lambda r: rd.textbook_residual(base, r, gain),
            "position_error": rd.position_error,
        }
        detectors = {"calibrated": lambda r, cal=cal: rd.calibrated(base, cal, r)}
        for name, signal in signals.items():
            if name not in methods:
                continue
            thresholds = rd.constant_thresholds([signal(r) for r in train])
            detectors[name] = lambda r, s=signal, th=thresholds: rd.with_threshold(r, s(r), th)
        for name, detect in detectors.items():
            for key, recs in (("held_clean", held), ("pert", pert)):
                dets = [detect(r) for r in recs]
                scores[name][key].append(
                    [rd.score(dets, recs, joint=j) for j in range(len(joints))]
                )
                if key == "held_clean":
                    floor[name] += [np.asarray(d.residual) for d in dets]
    out: dict[str, Any] = {}
    for name in methods:
        out[name + suffix] = {
            key: [rd.pooled([fold[j] for fold in scores[name][key]]) for j in range(len(joints))]
            for key in ("held_clean", "pert")
        }
        residual = np.concatenate(floor[name])
        out[name + suffix]["rms"] = np.sqrt(np.nanmean(residual**2, axis=0)).tolist()
        out[name + suffix]["peak"] = np.nanmax(np.abs(residual), axis=0).tolist()
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=10, help="clean and disturbed runs each")
    parser.add_argument("--gain", type=float, default=20.0)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).parent))
    from _results import write_results  # noqa: PLC0415

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        result = survey(Path(tmp), args.runs, args.gain)
    joints = result["joints"]
    lines = [
        f"A two-link robot written from scratch (benchmarks/independent_robot.py), "
        f"{args.runs} clean and {args.runs} disturbed runs of 10 s, 2 folds, K_o = "
        f"{args.gain:g} /s; the lab's URDF as the model.",
        "",
        "| detector | joint | pulses found | false alarms / min (disturbed) | delay median / p90 "
        "| false alarms / min (held-out clean) | held-out clean residual RMS / peak |",
        "|---|---|---|---|---|---|---|",
    ]
    data: dict[str, Any] = {}
    for name, row in result["methods"].items():
        for j, joint in enumerate(joints):
            s, c = row["pert"][j], row["held_clean"][j]
            lines.append(
                f"| {name} | {joint} | {s.found}/{s.pulses} ({s.recall:.0%}) | "
                f"{s.alarms_per_minute:.1f} | {s.delay_s(50) * 1e3:.0f} / "
                f"{s.delay_s(90) * 1e3:.0f} ms | {c.alarms_per_minute:.1f} | "
                f"{row['rms'][j]:.2f} / {row['peak'][j]:.2f} |"
            )
            data[f"{name}/{joint}"] = {
                "found": s.found, "pulses": s.pulses, "alarms_per_minute": s.alarms_per_minute,
                "delay_median_s": s.delay_s(50), "delay_p90_s": s.delay_s(90),
                "held_clean_alarms_per_minute": c.alarms_per_minute,
                "held_clean_rms": row["rms"][j], "held_clean_peak": row["peak"][j],
            }  # fmt: skip
    lines += ["", f"{time.perf_counter() - started:.0f} s (`.venv/bin/python "
              "benchmarks/independent_robot.py`)."]  # fmt: skip
    write_results(args.out, "independent_robot", lines, data)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
