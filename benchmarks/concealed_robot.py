"""Issue 27, part 4: effects concealed in the real pendubot runs, one kind per case, and the
robot discrepancy tool run blind on them.

    .venv/bin/python benchmarks/concealed_robot.py [--cases all|delay,gain,...] [--out DIR]

The recordings are real and were made by others: the DFKI Underactuated Lab's double pendulum in
pendubot mode (../shared/external/double_pendulum, the 10 runs without disturbances, BSD-3), the
shoulder driven, the elbow passive. Each case rewrites the runs so that their real motion is
what a robot with the effect would have done under the rewritten command (the robot's torque
balance: applied(command') - effect = what moved the real robot = tau_con):

* command_delay d: the motors act d late, so the command is advanced by d (interpolated on the
  recorded stamps): tau'(t) = tau(t + d);
* torque_gain g (shoulder): the motor applies g times its command: tau1' = tau1 / g;
* torque_saturation L (shoulder): the motor applies L tanh(tau1' / L): tau1' = L atanh(tau1 / L);
* torque_offset o (shoulder): a torque -o acts on the joint besides the model's: tau1' = tau1 + o;
* coulomb_friction c (shoulder): tau1' = tau1 + c sign(q1'), q1' the recorded speed smoothed;
* cogging A at N periods per revolution (shoulder): tau1' = tau1 + A sin(N q1);
* payload m at r on the elbow link (a point mass on its axis): tau' = tau + the point mass's
  torques, M(q) q'' + C(q, q') q' - G(q) of the lab's equations with m2 = m, r2 = r, I2 = m r^2
  (q', q'' from the recorded positions by a Savitzky-Golay filter);
* sensor_delay d: the positions and speeds recorded d late: q'(t) = q(t - d);
* quantization s: the positions of both joints coarsened to multiples of s (named on either).

None of this shares code with the tool (numpy, scipy and the lab's published equations). The
tool runs as a user runs it (`transparency discrepancy RUN.csv ... --urdf pendubot.urdf --json`,
its own defaults: every third run held out), first on the unchanged runs (the baseline: what the
URDF misses on the real robot), then on each case. A case counts as **named** when the
concealed kind is among the findings on the joint it was concealed on with its parameter within
30 % of the concealed value (relative to the baseline: a gain as the ratio of the named gains,
a delay, offset or friction as the difference), and as **clean** when nothing else is named
beyond the baseline's findings (by kind and joint). Writes results/concealed_robot.md, .json.
"""

from __future__ import annotations

import argparse
import json
import lzma
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _results import write_results  # noqa: E402

DATA = ROOT.parent / "shared" / "external" / "double_pendulum"
SHOULDER, ELBOW = "Joint1", "Joint2"  # the URDF's joint names
BOTH = "both"  # an effect concealed on every joint (the tool names it per joint)
G = 9.81
L1 = 0.2  # the lab's model_parameters.yml: l1 [m]
Columns = dict[str, np.ndarray]


def _read(path: Path) -> tuple[list[str], Columns]:
    with lzma.open(path, "rt") as f:
        header = f.readline().strip().split(",")
        values = np.loadtxt(f, delimiter=",", ndmin=2)
    return header, {name: values[:, i].copy() for i, name in enumerate(header)}


def _write(path: Path, header: list[str], cols: Columns) -> None:
    table = np.stack([cols[name] for name in header], axis=1)
    np.savetxt(path, table, delimiter=",", header=",".join(header), comments="", fmt="%.17g")


def _smooth(cols: Columns, name: str, deriv: int) -> np.ndarray:
    """A Savitzky-Golay estimate (41 samples, cubic) on the runs' median step."""
    dt = float(np.median(np.diff(cols["time"])))
    return np.asarray(savgol_filter(cols[name], 41, 3, deriv=deriv, delta=dt), dtype=float)


def _shift(cols: Columns, names: tuple[str, ...], by_s: float) -> None:
    """Each column at t + by_s (held at the ends)."""
    t = cols["time"]
    for name in names:
        cols[name] = np.interp(t + by_s, t, cols[name])


def command_delay(cols: Columns, d: float) -> None:
    _shift(cols, ("tau_con1", "tau_con2"), d)


def torque_gain(cols: Columns, g: float) -> None:
    cols["tau_con1"] = cols["tau_con1"] / g


def torque_saturation(cols: Columns, limit: float) -> None:
    cols["tau_con1"] = limit * np.arctanh(cols["tau_con1"] / limit)


def torque_offset(cols: Columns, o: float) -> None:
    cols["tau_con1"] = cols["tau_con1"] + o


def coulomb_friction(cols: Columns, c: float) -> None:
    cols["tau_con1"] = cols["tau_con1"] + c * np.sign(_smooth(cols, "pos_meas1", 1))


def cogging(cols: Columns, amplitude: float, periods: float) -> None:
    cols["tau_con1"] = cols["tau_con1"] + amplitude * np.sin(periods * cols["pos_meas1"])


def payload(cols: Columns, m: float, r: float) -> None:
    """A point mass m on the elbow link's axis at r from the elbow: its share of the lab's
    equations (M q'' + C q' - G with link 2's m2 = m, r2 = r, I2 = m r^2; q = 0 hangs down)."""
    q1, q2 = cols["pos_meas1"], cols["pos_meas2"]
    v1, v2 = _smooth(cols, "pos_meas1", 1), _smooth(cols, "pos_meas2", 1)
    a1, a2 = _smooth(cols, "pos_meas1", 2), _smooth(cols, "pos_meas2", 2)
    c2, s2 = np.cos(q2), np.sin(q2)
    i2 = m * r * r
    m00 = i2 + m * L1 * L1 + 2 * m * L1 * r * c2
    m01 = i2 + m * L1 * r * c2
    h = m * L1 * r * s2
    g1 = m * G * (L1 * np.sin(q1) + r * np.sin(q1 + q2))
    g2 = m * G * r * np.sin(q1 + q2)
    cols["tau_con1"] = cols["tau_con1"] + m00 * a1 + m01 * a2 - h * (2 * v1 * v2 + v2 * v2) + g1
    cols["tau_con2"] = cols["tau_con2"] + m01 * a1 + i2 * a2 + h * v1 * v1 + g2


def sensor_delay(cols: Columns, d: float) -> None:
    _shift(cols, ("pos_meas1", "pos_meas2", "vel_meas1", "vel_meas2"), -d)


def quantization(cols: Columns, step: float) -> None:
    for name in ("pos_meas1", "pos_meas2"):
        cols[name] = step * np.round(cols[name] / step)


@dataclass(frozen=True)
class Case:
    name: str
    kind: str  # the tool's name for it
    joint: str | None  # None: the whole robot; BOTH: each joint
    parameter: str  # the JSON parameter compared
    value: float
    relative: str  # "ratio" or "difference" against the baseline's finding
    apply: Callable[[Columns], None]


CASES = [
    Case("delay", "command_delay", None, "delay_s", 0.010, "difference",
         lambda c: command_delay(c, 0.010)),
    Case("gain", "torque_gain", SHOULDER, "gain", 0.7, "ratio", lambda c: torque_gain(c, 0.7)),
    Case("saturation", "torque_saturation", SHOULDER, "limit_nm", 6.25, "difference",
         lambda c: torque_saturation(c, 6.25)),
    Case("offset", "torque_offset", SHOULDER, "offset_nm", 0.3, "difference",
         lambda c: torque_offset(c, 0.3)),
    Case("coulomb", "coulomb_friction", SHOULDER, "coulomb_nm", 0.3, "difference",
         lambda c: coulomb_friction(c, 0.3)),
    Case("cogging", "cogging", SHOULDER, "amplitude_nm", 0.2, "difference",
         lambda c: cogging(c, 0.2, 12)),
    Case("payload", "payload", ELBOW, "mass_kg", 0.3, "difference",
         lambda c: payload(c, 0.3, 0.3)),
    Case("sensor_delay", "sensor_delay", None, "delay_s", 0.005, "difference",
         lambda c: sensor_delay(c, 0.005)),
    Case("quantization", "quantization", BOTH, "step_rad", 0.01, "difference",
         lambda c: quantization(c, 0.01)),
]  # fmt: skip


def _run_tool(paths: list[Path]) -> tuple[dict, float]:
    command = [sys.executable, "-m", "transparency_ros", "discrepancy", *map(str, paths),
               "--urdf", str(DATA / "pendubot.urdf"), "--json"]  # fmt: skip
    start = time.monotonic()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run(command, capture_output=True, text=True, check=False, env=env)
    seconds = time.monotonic() - start
    if done.returncode != 0:
        raise RuntimeError(f"the tool failed ({done.returncode}): {done.stderr[-1500:]}")
    return json.loads(done.stdout), seconds


def _key(finding: dict) -> tuple[str, str | None]:
    return finding["effect"], finding["joint"]


def _concealed(finding: dict, case: Case) -> bool:
    """Whether ``finding`` names what ``case`` conceals (on its joint, or on any for BOTH)."""
    kind, joint = _key(finding)
    return kind == case.kind and case.joint in (BOTH, joint)


def _judge(case: Case, base: dict, result: dict) -> dict:
    base_keys = {_key(f) for f in base["findings"]}
    named = [f for f in result["findings"] if _concealed(f, case)]
    extra = [_key(f) for f in result["findings"]
             if _key(f) not in base_keys and not _concealed(f, case)]  # fmt: skip
    found = None
    if named:
        value = named[0]["parameters"].get(case.parameter)
        before = [f for f in base["findings"] if _key(f) == _key(named[0])]
        reference = before[0]["parameters"].get(case.parameter) if before else None
        if value is not None and case.relative == "ratio":
            found = value / (reference if reference else 1.0)
        elif value is not None:
            found = value - (reference or 0.0)
    within = found is not None and abs(found - case.value) <= 0.3 * abs(case.value)
    return {
        "case": case.name, "kind": case.kind, "joint": case.joint, "concealed": case.value,
        "parameter": case.parameter, "found": found, "named": within, "extra": extra,
        "clean": not extra,
        "findings": [(f["effect"], f["joint"], f["parameters"]) for f in result["findings"]],
        "heldout_rms_nm": result["heldout_rms_nm"],
    }  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="all", help="comma-separated case names, or all")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = parser.parse_args()
    chosen = CASES if args.cases == "all" else [c for c in CASES if c.name in args.cases.split(",")]
    runs = sorted(DATA.glob("pendubot_clean_*.csv.xz"))
    tables = [(p.name.removesuffix(".csv.xz"), *_read(p)) for p in runs]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        print(f"baseline: {len(runs)} unchanged runs ...", file=sys.stderr, flush=True)
        base, base_s = _run_tool(runs)
        for case in chosen:
            directory = Path(tmp) / case.name
            directory.mkdir()
            paths = []
            for name, header, cols in tables:
                changed = {k: v.copy() for k, v in cols.items()}
                case.apply(changed)
                paths.append(directory / f"{name}.csv")
                _write(paths[-1], header, changed)
            print(f"{case.name} ...", file=sys.stderr, flush=True)
            result, seconds = _run_tool(paths)
            row = _judge(case, base, result)
            row["seconds"] = round(seconds, 1)
            rows.append(row)
            print(f"  {row['named']=} found={row['found']} extra={row['extra']}",
                  file=sys.stderr, flush=True)  # fmt: skip
    named = sum(r["named"] for r in rows)
    clean = sum(r["named"] and r["clean"] for r in rows)
    lines = [
        "# Effects concealed in the real pendubot runs (issue 27, part 4)",
        "",
        f"`.venv/bin/python benchmarks/concealed_robot.py` ({len(runs)} real runs, "
        f"every third held out; baseline {base_s:.0f} s)",
        "",
        "Baseline (unchanged runs) names: "
        + (
            ", ".join(f"{f['effect']}[{f['joint']}] {f['parameters']}" for f in base["findings"])
            or "nothing"
        ),
        "",
        "| case | concealed | named as | within 30 % | else named | s |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        found = "-" if r["found"] is None else f"{r['found']:.4g}"
        lines.append(
            f"| {r['case']} | {r['parameter']} = {r['concealed']:g} | {found} | "
            f"{'yes' if r['named'] else 'no'} | {', '.join(map(str, r['extra'])) or '-'} | "
            f"{r['seconds']:.0f} |"
        )
    lines += ["", f"**{named} of {len(rows)}** named within 30 %, {clean} of them with nothing "
              "else named."]  # fmt: skip
    write_results(args.out, "concealed_robot", lines, {
        "baseline": base, "baseline_seconds": base_s, "cases": rows, "named": named,
        "clean": clean,
    })  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
