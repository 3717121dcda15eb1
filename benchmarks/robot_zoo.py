"""Robots with several effects concealed at once, to set the robot discrepancy tool's rule on a
distribution of robots rather than on the real pendubot (issue 27).

    .venv/bin/python benchmarks/robot_zoo.py make DIR --seeds 300-329
    .venv/bin/python benchmarks/robot_zoo.py survey DIR [--share S] [--keep S] [--jobs 2] \
        [--log LOG.jsonl.gz] [--out DIR]
    .venv/bin/python benchmarks/robot_zoo.py table LOG.jsonl.gz [--out DIR]

Seeds 100-129 were developed on; figures are reported on seeds first run after the code.

Nothing here comes from the package: ``make`` integrates the DFKI lab's equations of motion
(benchmarks/independent_robot.py's ``Plant``, written from the lab's README; RK4 at 0.25 ms,
all robots' runs at once) with per-robot physics drawn from the seed. The tool is given the
lab's URDF, with its real faults (inertias about the joint axes written as about the centres of
mass, no rotor inertia), so every robot's model is wrong there before anything is concealed.

Per robot (seed): both joints driven (computed torque with the lab's model plus PD, sums of two
sines) or the shoulder alone (a pendubot: the elbow passive); friction drawn around the lab's
(Coulomb 0.5-2x, viscous 1-5x, as atan(100 q')); a motor lag of 0.3-1 ms; an encoder of 2^14
counts; the velocity the drives report low-passed at 250 Hz (not what the tool reads). Then 0,
1, 2 or 3 effects concealed, of distinct kinds, each on a joint drawn at random (a gain or a
saturation on a driven joint only):

* command_delay 4-15 ms (the motors act on the command that late: a command history);
* sensor_delay 3-10 ms (the encoders read that late; the controller sees it too);
* torque_gain 0.6-0.8 or 1.25-1.6 (the motor applies that times its command);
* torque_saturation L tanh(c / L), L 0.5-0.8 of the joint's largest command in the run;
* torque_offset +-0.1-0.4 N m; coulomb_friction +0.1-0.4 N m (tanh(q' / 0.02), another law
  than the baseline's); cogging 0.05-0.3 N m at 6-40 periods per revolution;
* payload 0.2-0.6 kg on the elbow link, 0.15-0.3 m out along it (lab equations: m2, r2, I2);
* quantization: an encoder of 2^9-2^10 counts (steps 6-12 mrad).

With ``make --model-error`` every robot also has physics that none of the tool's candidates
describes (the real pendubot keeps such a residual, docs/robots.md): friction growing with the
motor's load, 0.03-0.1 |applied torque| against the motion on each joint (a geared motor's),
and a cable across the elbow, a spring of 0.05-0.2 N m/rad about a rest angle of +-0.5 rad. It
is drawn from a stream of its own (the seed + 20000): the rest of the robot is the seed's
without it. Nothing the tool names for it counts as right: it is neither required nor allowed.

``answers.yaml`` per robot: ``required`` (``kind[joint]``, or ``command_delay`` for the whole
robot) with ``params`` (the issue's parameter names; what the robot has against its URDF: a
delay with the command's hold over half a control period and the motor's lag added, a Coulomb
friction with the baseline draw's difference from the URDF's added), ``allowed`` (what the
URDF's faults and the friction draws make true on every robot: parameter_drift, friction and
the rotors' inertia (armature: the lab's equations have it, the URDF has not) on either joint;
a delay twin of a concealed delay, which the balance cannot tell apart; a command
delay or its twin within ``LAG_ALLOWED_S`` of zero). A quantization counts on either joint.

``survey`` runs the tool (the package's Python entry points, as the CLI does; ``--share`` and
``--keep`` set the loop's shares in the search and on the final model, to compare rules) on
every robot and scores it: a required effect is **named** when its kind is found on its joint
with its parameter within 30 % (periods per revolution exact); a robot is **fully right** when every
required effect is named and nothing outside required and allowed is. ``--log`` also writes
every single step the loop tried (its share of the error, information-criterion change, whether
it was meaningful), JSON lines, to set a rule from.
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import sys
import time
import xml.etree.ElementTree as ET
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).parent))
from independent_robot import (
    KD,
    KP,
    LAB,
    STEP_S,
    SUBSTEPS,
    Plant,
    desired,
    lab_parameters,
    per_run,
    rk4,
)

RUNS = 6
DURATION_S = 8.0
KINDS = (
    "command_delay", "sensor_delay", "torque_gain", "torque_saturation", "torque_offset",
    "coulomb_friction", "cogging", "payload", "quantization",
)  # fmt: skip
JOINTS = ("Joint1", "Joint2")  # the URDF's
LAG_ALLOWED_S = 0.003  # a command delay this small is the motors' lag, not a finding
TOLERANCE = 0.3
PARAMETERS = {  # what the tool reports per kind (the names)
    "command_delay": ("delay_s",), "sensor_delay": ("delay_s",), "torque_gain": ("gain",),
    "torque_saturation": ("limit_nm",), "torque_offset": ("offset_nm",),
    "coulomb_friction": ("coulomb_nm",), "cogging": ("amplitude_nm", "periods_per_rev"),
    "payload": ("mass_kg",),
}  # fmt: skip
# the torque balance shifts its two sides alike for either delay: the tool names one and the
# other as explained alike; either counts for the one concealed
TWINS = {"command_delay": "sensor_delay", "sensor_delay": "command_delay"}


def _parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


# ---------------------------------------------------------------------------- the robots


def draw(seed: int, model_error: bool = False) -> dict[str, Any]:
    """One robot's physics and concealed effects from ``seed``; with ``model_error``, also
    physics that none of the tool's candidates describes (``unmodelled``), drawn from a
    stream of its own, so the rest of the robot is the seed's without it."""
    rng = np.random.default_rng(seed)
    lab = lab_parameters()
    pendubot = bool(rng.random() < 0.5)
    driven = [0] if pendubot else [0, 1]
    robot: dict[str, Any] = {
        "seed": seed,
        "pendubot": pendubot,
        "cf": [lab["cf1"] * rng.uniform(0.5, 2.0), lab["cf2"] * rng.uniform(0.5, 2.0)],
        "b": [lab["b1"] * rng.uniform(1.0, 5.0), lab["b2"] * rng.uniform(1.0, 5.0)],
        "lag_s": float(rng.uniform(3e-4, 1e-3)),
        "amplitude": [float(rng.uniform(0.6, 1.2)), float(rng.uniform(0.4, 0.9))],
        "effects": [],
    }
    count = int(rng.choice([0, 1, 2, 3], p=[0.25, 0.3, 0.25, 0.2]))
    kinds = [str(k) for k in rng.permutation(KINDS)]
    if count and "command_delay" in kinds[:count] and "sensor_delay" in kinds[:count]:
        kinds.remove("sensor_delay")  # one delay at a time: the balance sees their sum
    for kind in kinds[:count]:
        joint = int(rng.choice(driven if kind in {"torque_gain", "torque_saturation"} else [0, 1]))
        e: dict[str, Any] = {"kind": kind, "joint": joint}
        if kind == "command_delay":
            e |= {"joint": None, "delay_s": float(rng.uniform(0.004, 0.015))}
        elif kind == "sensor_delay":
            e |= {"joint": None, "delay_s": float(rng.uniform(0.003, 0.010))}
        elif kind == "torque_gain":
            e["gain"] = float(rng.choice([rng.uniform(0.6, 0.8), rng.uniform(1.25, 1.6)]))
        elif kind == "torque_saturation":
            e["fraction"] = float(rng.uniform(0.5, 0.8))  # of the joint's largest command
        elif kind == "torque_offset":
            e["offset_nm"] = float(rng.choice([-1, 1]) * rng.uniform(0.1, 0.4))
        elif kind == "coulomb_friction":
            e["coulomb_nm"] = float(rng.uniform(0.1, 0.4))
        elif kind == "cogging":
            e |= {"amplitude_nm": float(rng.uniform(0.05, 0.3)),
                  "periods_per_rev": int(rng.integers(6, 41)),
                  "phase_rad": float(rng.uniform(-math.pi, math.pi))}  # fmt: skip
        elif kind == "payload":
            e |= {"joint": 1, "mass_kg": float(rng.uniform(0.2, 0.6)),
                  "distance_m": float(rng.uniform(0.15, 0.3))}  # fmt: skip
        elif kind == "quantization":
            e |= {"joint": None, "counts": int(rng.choice([512, 768, 1024]))}
        robot["effects"].append(e)
    if model_error:
        other = np.random.default_rng(seed + 20_000)
        robot["unmodelled"] = {
            # friction growing with the motor's load, as a geared motor's does
            "load_friction": [float(other.uniform(0.03, 0.1)), float(other.uniform(0.03, 0.1))],
            # a cable across the elbow: a spring about an angle of its own
            "cable_nm_per_rad": float(other.uniform(0.05, 0.2)),
            "cable_rest_rad": float(other.uniform(-0.5, 0.5)),
        }
    return robot


def _effect(robot: dict[str, Any], kind: str) -> dict[str, Any] | None:
    return next((e for e in robot["effects"] if e["kind"] == kind), None)


def simulate(
    robot: dict[str, Any], runs: int = RUNS, duration_s: float = DURATION_S
) -> list[dict[str, np.ndarray]]:
    """The robot's runs, per run its columns (the lab's names)."""
    rng = np.random.default_rng(robot["seed"] + 10_000)
    lab = lab_parameters()
    model = Plant(lab)  # the controller's
    true = dict(lab, cf1=robot["cf"][0], cf2=robot["cf"][1], b1=robot["b"][0], b2=robot["b"][1])
    payload = _effect(robot, "payload")
    if payload is not None:  # a point mass on the elbow link's axis
        m, r = payload["mass_kg"], payload["distance_m"]
        true["r2"] = (lab["m2"] * lab["r2"] + m * r) / (lab["m2"] + m)
        true["m2"] = lab["m2"] + m
        true["I2"] = lab["I2"] + m * r**2  # (the lab's I2 is about the joint's axis)
    plant = Plant(true)
    driven = np.array([1.0, 0.0 if robot["pendubot"] else 1.0])
    amp = np.array(robot["amplitude"]) * driven  # (a pendubot's elbow follows no reference)
    ref = np.stack([rng.uniform(0.5, 1.0, (runs, 2, 2)) * amp[:, None],
                    2 * math.pi * rng.uniform(0.3, 1.0, (runs, 2, 2)),
                    rng.uniform(0, 2 * math.pi, (runs, 2, 2))], -1)  # fmt: skip
    gain = np.ones(2)
    if (e := _effect(robot, "torque_gain")) is not None:
        gain[e["joint"]] = e["gain"]
    offset, coulomb, cog_a, cog_n, cog_phi = (np.zeros(2) for _ in range(5))
    if (e := _effect(robot, "torque_offset")) is not None:
        offset[e["joint"]] = e["offset_nm"]
    if (e := _effect(robot, "coulomb_friction")) is not None:
        coulomb[e["joint"]] = e["coulomb_nm"]
    if (e := _effect(robot, "cogging")) is not None:
        cog_a[e["joint"]], cog_n[e["joint"]] = e["amplitude_nm"], e["periods_per_rev"]
        cog_phi[e["joint"]] = e["phase_rad"]
    sat = _effect(robot, "torque_saturation")
    cmd_delay = e["delay_s"] if (e := _effect(robot, "command_delay")) else 0.0
    sen_delay = e["delay_s"] if (e := _effect(robot, "sensor_delay")) else 0.0
    quant = _effect(robot, "quantization")
    step = 2 * math.pi / (quant["counts"] if quant else 2**14)
    lag = robot["lag_s"]
    limit = np.full(2, np.inf)
    if sat is not None:  # its limit from a run without it: the joint's largest command
        probe = dict(
            robot, effects=[e for e in robot["effects"] if e["kind"] != "torque_saturation"]
        )
        peak = max(
            np.max(np.abs(r[f"tau_con{sat['joint'] + 1}"]))
            for r in simulate(probe, runs, duration_s)
        )
        limit[sat["joint"]] = sat["fraction"] * peak
        sat["limit_nm"] = float(limit[sat["joint"]])

    unmodelled = robot.get("unmodelled")
    load = np.array(unmodelled["load_friction"]) if unmodelled else np.zeros(2)
    cable = np.array([0.0, unmodelled["cable_nm_per_rad"]]) if unmodelled else np.zeros(2)
    rest = np.array([0.0, unmodelled["cable_rest_rad"]]) if unmodelled else np.zeros(2)

    def applied(current: np.ndarray, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        tau = gain * current
        for j in np.flatnonzero(np.isfinite(limit)):
            tau[:, j] = limit[j] * np.tanh(tau[:, j] / limit[j])
        sliding = np.tanh(v / 0.02)  # (the Coulomb law's and the load friction's)
        return (tau - offset - coulomb * sliding + cog_a * np.sin(cog_n * q + cog_phi)
                - load * np.abs(tau) * sliding - cable * (q - rest))  # fmt: skip

    def derivative(state: np.ndarray, command: np.ndarray) -> np.ndarray:
        qs, vs, cs = state[:, 0:2], state[:, 2:4], state[:, 4:6]
        return np.concatenate(
            [vs, plant.acceleration(qs, vs, applied(cs, qs, vs)), (command - cs) / lag], 1
        )

    samples = round(duration_s / (STEP_S * SUBSTEPS))
    q, v, current = np.zeros((runs, 2)), np.zeros((runs, 2)), np.zeros((runs, 2))
    # histories for the delays, on the integration step
    keep = int(0.02 / STEP_S) + 2
    q_hist = [q.copy()] * keep
    cmd_hist = [np.zeros((runs, 2))] * (int(0.02 / (STEP_S * SUBSTEPS)) + 2)
    v_report = np.zeros((runs, 2))
    alpha = 1 - math.exp(-2 * math.pi * 250.0 * STEP_S)
    encoder = np.zeros((runs, 2))
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("time", "pos_meas", "vel_meas", "tau_con")}
    lag_steps = sen_delay / STEP_S
    for k in range(samples):
        t = k * STEP_S * SUBSTEPS
        qd, vd, ad = desired(ref, t)
        tau_con = (model.inverse(qd, vd, ad) + KP * (qd - encoder) + KD * (vd - v_report)) * driven
        tau_con = np.clip(tau_con, -10.0, 10.0)
        for name, value in (("time", np.full(runs, t)), ("pos_meas", encoder.copy()),
                            ("vel_meas", v_report.copy()), ("tau_con", tau_con)):  # fmt: skip
            cols[name].append(value)
        cmd_hist = [*cmd_hist[1:], tau_con]
        for s in range(SUBSTEPS):
            # the command the motors act on: cmd_delay late (held between control steps)
            back = (cmd_delay - s * STEP_S) / (STEP_S * SUBSTEPS)
            command = cmd_hist[-1 - max(0, math.ceil(back))] if back > 0 else tau_con
            state = rk4(derivative, np.concatenate([q, v, current], 1), command)
            q, v, current = state[:, 0:2], state[:, 2:4], state[:, 4:6]
            q_hist = [*q_hist[1:], q.copy()]
            lo = math.floor(lag_steps)
            frac = lag_steps - lo
            seen = (1 - frac) * q_hist[-1 - lo] + frac * q_hist[-2 - lo]
            new = np.round(seen / step) * step
            v_report += alpha * ((new - encoder) / STEP_S - v_report)
            encoder = new
    return per_run(cols, runs)


def _urdf_friction() -> list[float]:
    """The URDF's Coulomb friction per joint (its ``dynamics friction``), read as XML."""
    root = ET.parse(LAB / "pendubot.urdf").getroot()
    by_name = {j.get("name"): j for j in root.findall("joint")}
    return [float(by_name[n].find("dynamics").get("friction")) for n in JOINTS]  # type: ignore[union-attr]


def answers(robot: dict[str, Any]) -> dict[str, Any]:
    """required (with params) and allowed, by ``kind[joint]`` (the whole robot: ``kind``).

    A required parameter is what the robot has against its URDF, the effect concealed on
    top of what every robot of the zoo has: a delay adds to the command's hold over half a
    control period and the motor's lag (which the balance sees as a delay of the command,
    whichever delay is concealed), a Coulomb friction to the baseline's against the URDF's
    (the lab's law cf atan(100 q') levels off at cf pi / 2; the URDF says cf)."""
    required: dict[str, dict[str, float]] = {}
    base_delay = 0.5 * STEP_S * SUBSTEPS + robot["lag_s"]
    urdf_cf = _urdf_friction()
    for e in robot["effects"]:
        kind = e["kind"]
        name = kind if e["joint"] is None else f"{kind}[{JOINTS[e['joint']]}]"
        if kind == "quantization":
            params = {"step_rad": 2 * math.pi / e["counts"]}
        else:
            params = {n: e[n] for n in PARAMETERS[kind]}
        if kind in TWINS:
            params = {"delay_s": e["delay_s"] + base_delay}
        if kind == "coulomb_friction":
            j = e["joint"]
            params = {"coulomb_nm": robot["cf"][j] * math.pi / 2 - urdf_cf[j] + e["coulomb_nm"]}
        if kind == "quantization":  # the tool names it per joint: either joint's counts
            for j in JOINTS:
                required[f"quantization[{j}]"] = params
            continue
        required[name] = params
    # (every robot's: the URDF's inertias, friction, and the rotors' inertia, which the lab's
    # equations have (gr^2 Ir on each joint, -gr Ir between them) and the URDF has not)
    baseline = ("parameter_drift", "coulomb_friction", "viscous_friction", "armature")
    allowed = [f"{k}[{j}]" for j in JOINTS for k in baseline]
    if "command_delay" in required:
        allowed.append("sensor_delay")
    if "sensor_delay" in required:
        allowed.append("command_delay")
    return {"required": required, "allowed": allowed, "robot": robot}


def make(directory: Path, seeds: list[int], model_error: bool = False) -> None:
    for seed in seeds:
        out = directory / f"robot_{seed}"
        if (out / "answers.yaml").exists():
            continue
        started = time.perf_counter()
        robot = draw(seed, model_error)
        runs = simulate(robot)
        out.mkdir(parents=True, exist_ok=True)
        for k, run in enumerate(runs):
            names = list(run)
            table = np.stack([run[n] for n in names], 1)
            np.savetxt(out / f"run_{k:02d}.csv", table, delimiter=",", header=",".join(names),
                       comments="", fmt="%.9g")  # fmt: skip
        (out / "answers.yaml").write_text(yaml.safe_dump(answers(robot), sort_keys=False))
        print(f"robot_{seed}: {[e['kind'] for e in robot['effects']] or 'nothing'} "
              f"({time.perf_counter() - started:.0f} s)", flush=True)  # fmt: skip


# ---------------------------------------------------------------------------- the survey


def run_tool(
    directory: Path, share: float | None, log: bool, keep: float | None = None
) -> dict[str, Any]:
    """The tool on one robot's runs; its findings, and (``log``) every single step tried.
    ``share``: the loop's share (None: the tool's); ``keep``: another share for the second
    look at each effect on the final model (``revisit.still_needed``; None: the same)."""
    from transparency_ros.analysis.discrepancy import discover as d  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.robot import RobotProblem, robot_result  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.steps import null_inside  # noqa: PLC0415
    from transparency_ros.analysis.robot_data import Columns, read_joint_csv  # noqa: PLC0415
    from transparency_ros.core.robot_model import RobotModel  # noqa: PLC0415

    steps: list[dict[str, Any]] = []

    class Logged(d.Discoverer):
        def _single(self, effects, params, cand, base, **kw):  # type: ignore[no-untyped-def]
            s = super()._single(effects, params, cand, base, **kw)
            if log:
                steps.append({
                    "before": [e.name for e in base.effects], "cand": cand.name,
                    "gain": float(s.gain), "judged": [float(x) for x in s.judged],
                    "daic": float(s.aic - base.aic), "meaningful": bool(s.meaningful),
                    "null_in": bool(null_inside(s)), "names": bool(self._names(s, base)),
                    "params": [float(v) for v in s.params[-1]],
                })  # fmt: skip
            return s

    started = time.perf_counter()
    model = RobotModel.from_urdf(LAB / "pendubot.urdf")
    columns = Columns.parse("time=time,position=pos_meas{},velocity=vel_meas{},torque=tau_con{}")
    recs = [
        read_joint_csv(f, list(model.joint_names), columns)
        for f in sorted(directory.glob("run_*.csv"))
    ]
    problem = RobotProblem(model, recs)
    kwargs = {} if share is None else {"min_improvement": share}
    loop = Logged(problem, **kwargs)
    if keep is not None:
        loop.keep_improvement = keep
    report = loop.run()
    result = robot_result(problem, report)
    return {"robot": directory.name, "findings": result["findings"], "steps": steps,
            "seconds": time.perf_counter() - started}  # fmt: skip


def score(found: list[dict[str, Any]], truth: dict[str, Any]) -> dict[str, Any]:
    named: dict[str, dict[str, float]] = {}
    for f in found:
        key = f["effect"] if f["joint"] is None else f"{f['effect']}[{f['joint']}]"
        named[key] = f["parameters"]
    required = truth["required"]
    hits, misses = [], []
    quant = [k for k in required if k.startswith("quantization")]
    for key, params in required.items():
        if key in quant:
            continue
        got = named.get(key)
        if got is None and key in TWINS:  # the balance cannot tell the two delays apart
            got = named.get(TWINS[key])
        ok = got is not None and all(_close(n, v, got.get(n)) for n, v in params.items())
        (hits if ok else misses).append(key)
    if quant:  # either joint's lattice
        ok = any(
            k in named and _close("step_rad", required[k]["step_rad"], named[k].get("step_rad"))
            for k in quant
        )
        (hits if ok else misses).append("quantization")
    extra = [
        k
        for k in named
        if k not in required
        and k not in truth["allowed"]
        and not (k in TWINS and abs(named[k].get("delay_s", 1.0)) <= LAG_ALLOWED_S)
    ]
    return {"named": hits, "missed": misses, "extra": extra,
            "right": not misses and not extra}  # fmt: skip


def _close(name: str, truth: float, got: float | None) -> bool:
    if got is None:
        return False
    if name == "periods_per_rev":
        return round(got) == round(truth)
    return abs(got - truth) <= TOLERANCE * abs(truth)


def _survey_one(args: tuple[Path, float | None, bool, float | None]) -> dict[str, Any]:
    directory, share, log, keep = args
    truth = yaml.safe_load((directory / "answers.yaml").read_text())
    if "robot" in truth:  # (scored by today's rules: robots made before a rule changed)
        truth = answers(truth["robot"])
    try:
        out = run_tool(directory, share, log, keep)
    except Exception as err:  # noqa: BLE001 - a failure is a result here, with its reason
        out = {
            "robot": directory.name,
            "findings": [],
            "steps": [],
            "error": f"{type(err).__name__}: {err}",
        }
    out["score"] = score(out["findings"], truth)
    if "error" in out:  # the tool failed: nothing about this robot is right
        out["score"]["right"] = False
    out["truth"] = {"required": truth["required"], "allowed": truth["allowed"]}
    return out


def survey(
    directory: Path, share: float | None, jobs: int, log: Path | None, keep: float | None = None
) -> list[dict[str, Any]]:
    robots = sorted(p for p in directory.glob("robot_*") if (p / "answers.yaml").exists())
    rows = []
    with Pool(jobs) as pool:
        for row in pool.imap(_survey_one, [(r, share, log is not None, keep) for r in robots]):
            s = row["score"]
            print(f"{row['robot']}: {'right' if s['right'] else 'wrong'}; named {s['named']}, "
                  f"missed {s['missed']}, extra {s['extra']} ({row.get('seconds', 0):.0f} s)"
                  + (f" ERROR {row['error']}" if "error" in row else ""), flush=True)  # fmt: skip
            rows.append(row)
            if log is not None:
                with gzip.open(log, "at") as f:
                    f.write(json.dumps(row) + "\n")
    return rows


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The survey's figures: robots fully right, required effects named (per kind), robots
    without a concealed effect that name nothing outside allowed, false findings (per kind)."""
    per_kind: dict[str, list[int]] = {}
    for r in rows:
        for key, hit in [(k, 1) for k in r["score"]["named"]] + [
            (k, 0) for k in r["score"]["missed"]
        ]:
            per_kind.setdefault(key.split("[")[0], []).append(hit)
    false: dict[str, int] = {}
    for r in rows:
        for key in r["score"]["extra"]:
            false[key.split("[")[0]] = false.get(key.split("[")[0], 0) + 1
    clean = [r for r in rows if not r["truth"]["required"]]
    return {
        "robots": len(rows),
        "fully_right": sum(r["score"]["right"] for r in rows),
        "required": sum(len(v) for v in per_kind.values()),
        "named": sum(sum(v) for v in per_kind.values()),
        "per_kind": {k: [sum(v), len(v)] for k, v in sorted(per_kind.items())},
        "effect_free": len(clean),
        "effect_free_clean": sum(not r["score"]["extra"] for r in clean),
        "false_findings": sum(false.values()),
        "false_per_kind": dict(sorted(false.items())),
        "errors": sum("error" in r for r in rows),
        "median_s": float(np.median([r.get("seconds", math.nan) for r in rows])),
    }


def report(rows: list[dict[str, Any]], command: str, out: str | None) -> None:
    s = summary(rows)
    lines = [
        "# Robots with effects concealed (benchmarks/robot_zoo.py)",
        "",
        f"`{command}`",
        "",
        f"- fully right (every concealed effect named within 30 %, nothing outside allowed): "
        f"**{s['fully_right']}/{s['robots']}**",
        f"- concealed effects named: {s['named']}/{s['required']} "
        + ", ".join(f"{k} {a}/{b}" for k, (a, b) in s["per_kind"].items()),
        f"- robots with nothing concealed that name nothing outside allowed: "
        f"{s['effect_free_clean']}/{s['effect_free']}",
        f"- false findings: {s['false_findings']} "
        + ", ".join(f"{k} {n}" for k, n in s["false_per_kind"].items()),
        f"- tool errors: {s['errors']}; median {s['median_s']:.0f} s per robot",
        "",
        "| robot | concealed | named right | missed | named outside allowed | s |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        sc = r["score"]
        lines.append(
            f"| {r['robot']} | {', '.join(r['truth']['required']) or '-'} | "
            f"{', '.join(sc['named']) or '-'} | {', '.join(sc['missed']) or '-'} | "
            f"{', '.join(sc['extra']) or '-'} | {r.get('seconds', math.nan):.0f} |"
        )
    if out is None:
        print("\n".join(lines[:12]))
        return
    from _results import write_results  # noqa: PLC0415

    kept = [{k: v for k, v in r.items() if k != "steps"} for r in rows]  # (steps: in --log)
    write_results(out, "robot_zoo", lines, {"summary": s, "robots": kept})


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("make", help="write robots (CSV runs and answers.yaml per seed)")
    m.add_argument("directory")
    m.add_argument("--seeds", default="100-119")
    m.add_argument(
        "--model-error",
        action="store_true",
        help="also physics no candidate describes (load-dependent friction, an elbow cable)",
    )
    s = sub.add_parser("survey", help="run the tool on every robot in DIR and score it")
    s.add_argument("directory")
    s.add_argument(
        "--share", type=float, default=None, help="the loop's share (default: the tool's)"
    )
    s.add_argument(
        "--keep", type=float, default=None, help="the share on the final model (default: --share)"
    )
    s.add_argument("--jobs", type=int, default=2)
    s.add_argument("--log", default=None, help="JSON lines (gzip) of every robot's steps")
    s.add_argument("--out", default=None, help="write robot_zoo.md and .json here")
    t = sub.add_parser("table", help="the survey's figures from its --log")
    t.add_argument("log")
    t.add_argument("--out", default=None, help="write robot_zoo.md and .json here")
    args = parser.parse_args(argv)
    if args.command == "table":
        with gzip.open(args.log, "rt") as f:
            rows = [{k: v for k, v in json.loads(line).items() if k != "steps"} for line in f]
        report(rows, " ".join(["benchmarks/robot_zoo.py", *(argv or sys.argv[1:])]), args.out)
    elif args.command == "make":
        make(Path(args.directory), _parse_seeds(args.seeds), args.model_error)
    else:
        log = Path(args.log) if args.log else None
        rows = survey(Path(args.directory), args.share, args.jobs, log, args.keep)
        command = " ".join(["benchmarks/robot_zoo.py", *(argv or sys.argv[1:])])
        report(rows, command, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
