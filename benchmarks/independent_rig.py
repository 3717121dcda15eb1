"""A drop-test rig written from scratch, to try the discrepancy tool on data it did not shape.

    .venv/bin/python benchmarks/independent_rig.py [--seeds 300:330] [--jobs 2] [--out DIR]

Nothing here comes from the package: not its physics, integrator, contact or friction law, bag
writer or conventions. It reads only Table 1 and the drop-test settings (config/*.yaml, plain
YAML) and writes bags with rosbags to the bag contract of docs/drop_test.md, which is all a
rig elsewhere would know of this project.

The rig: a shuttle falls on a vertical rail onto the tip of an arm turned by the actuator under
an impedance law tau = k_s (theta_d - phi), limited to the peak torque. Motor and arm are one
body, or two joined through a dead band when there is backlash. Contact is Hunt-Crossley,
F = k d^n (1 + alpha d'), n = 1.5 (a metal contact, 1e8-1e9 N/m^1.5) or 1 (a compliant one);
its damping sets the restitution. Friction is Stribeck, (tau_c + (tau_s - tau_c)
exp(-(w / w_s)^2)) tanh(w / eps) + b w. The shuttle's weight acts through the contact force
whenever it rests on the arm, as on any real rig. Integrated with fixed-step RK4 at 10 us, all
trials of a campaign at once.

Drawn per campaign from its seed, besides the hidden effect: the actuator; which way a strike
turns the arm (and whether the bag declares it); whether the recording holds the shuttle before
its release or is triggered 0.05-0.2 s before contact; whether /joint_commands is recorded;
theta_d; the encoder's resolution (fine) and rate (500-2000 Hz); the DAQ's rate (5-20 kHz) and
noise; the contact's stiffness and the Stribeck shape within what is normal.

Hidden effects (at most one per campaign, a quarter of the campaigns none), named as the tool's
library names them: parameter_drift (J_r, b_v or tau_c off by x0.4-0.6 or x1.8-3), torque_offset,
stiction (tau_s 3-5 tau_c), restitution (e 0.4-0.7), impact_speed_loss (rail friction),
structural_compliance (a linear contact of 1e4-1e5 N/m), backlash, sensor_delay (the encoder's
stamps late), quantization (a coarse encoder). The labels go to labels.json, never read by the
tool. The survey runs the tool blind and scores it: single-effect recall, false findings on
campaigns with nothing hidden, the shuttle's weight named where it rests on the arm, precision.
Writes results/independent_rig.md.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
import tempfile
import time
from dataclasses import dataclass, field
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).parent))

CONFIG = Path(__file__).resolve().parents[1] / "config"
G = 9.80665
DT = 1e-5
AFTER_CONTACT_S = 0.35
HEIGHTS = (0.03, 0.06, 0.12, 0.2, 0.3, 0.45)
EFFECTS = (
    "parameter_drift",
    "torque_offset",
    "stiction",
    "restitution",
    "impact_speed_loss",
    "structural_compliance",
    "backlash",
    "sensor_delay",
    "quantization",
)


@dataclass
class Rig:
    actuator: str
    mass_kg: float
    arm_m: float
    arm_inertia: float
    rotor_inertia: float
    viscous: float
    coulomb: float
    static: float
    stribeck_w: float
    eps_w: float
    peak_torque: float
    k_s: float
    theta_d: float
    sign: int  # which way a strike turns the arm, in the rig's own angle
    contact_k: float
    contact_n: float
    contact_alpha: float
    rail_n: float = 0.0
    offset_nm: float = 0.0
    backlash_rad: float = 0.0
    delay_s: float = 0.0
    counts_per_rev: int = 1 << 17
    encoder_hz: float = 1000.0
    daq_hz: float = 10000.0
    force_noise_n: float = 0.05
    height_noise_m: float = 2e-5
    labels: dict[str, dict[str, float]] = field(default_factory=dict)


def table1(actuator: str) -> dict[str, Any]:
    data = yaml.safe_load((CONFIG / "actuators.yaml").read_text())
    return dict(data["actuators"][actuator])


def draw_rig(seed: int) -> tuple[Rig, dict[str, Any]]:
    rng = random.Random(seed)
    drop = yaml.safe_load((CONFIG / "drop_test.yaml").read_text())
    actuator = rng.choice(("U10DD", "EC60", "T2822", "U10GB"))
    t1 = table1(actuator)
    coulomb = float(t1["coulomb_friction_nm"])
    rig = Rig(
        actuator=actuator,
        mass_kg=float(drop["shuttle_mass_kg"][actuator]),
        arm_m=float(drop["arm_length_m"]),
        arm_inertia=float(drop["arm_inertia_kgm2"]),
        rotor_inertia=float(t1["reflected_inertia_kgm2"]),
        viscous=float(t1["viscous_damping_nms_per_rad"]),
        coulomb=coulomb,
        static=coulomb * rng.uniform(1.0, 1.2),  # a mild Stribeck hump is normal
        stribeck_w=rng.uniform(0.05, 0.3),
        eps_w=0.002,  # rad/s: a loaded arm at rest creeps about 1e-3 rad/s, below the encoder
        peak_torque=float(t1["peak_torque_nm"]),
        k_s=float(drop["k_s_nm_per_rad"]),
        theta_d=rng.uniform(-0.3, 0.3),
        sign=rng.choice((-1, 1)),
        # a metal contact: 0.5-2.5 MN/m under the resting shuttle's weight (1e6-1e7 N/m^1.5
        # would be 2e4-1e5 N/m there, which the tool rightly names structural_compliance)
        contact_k=10 ** rng.uniform(8.0, 9.0),
        contact_n=1.5,
        contact_alpha=rng.uniform(2.0, 4.0),  # s/m: nearly inelastic at these speeds
        counts_per_rev=1 << rng.randint(16, 19),
        encoder_hz=rng.choice((500.0, 1000.0, 2000.0)),
        daq_hz=rng.choice((5000.0, 10000.0, 20000.0)),
        force_noise_n=rng.uniform(0.02, 0.1),
        height_noise_m=rng.uniform(1e-5, 4e-5),
    )
    hidden = None if rng.random() < 0.25 else rng.choice(EFFECTS)
    if hidden == "parameter_drift":
        term = rng.choice(("reflected_inertia", "viscous", "coulomb"))
        scale = rng.choice((rng.uniform(0.4, 0.6), rng.uniform(1.8, 3.0)))
        if term == "reflected_inertia":
            rig.rotor_inertia *= scale
        elif term == "viscous":
            rig.viscous *= scale
        else:
            rig.coulomb *= scale
            rig.static = max(rig.static, rig.coulomb)
        rig.labels[hidden] = {f"{term}_scale": scale}
    elif hidden == "torque_offset":
        rig.offset_nm = rng.choice((-1, 1)) * rng.uniform(0.05, 0.3)
        rig.labels[hidden] = {"offset_nm": rig.offset_nm}
    elif hidden == "stiction":
        rig.static = rig.coulomb * rng.uniform(3.0, 5.0)
        rig.stribeck_w = rng.uniform(0.02, 0.1)
        rig.labels[hidden] = {"static_nm": rig.static}
    elif hidden == "restitution":
        e = rng.uniform(0.4, 0.7)
        rig.contact_alpha = 0.0  # set per trial from the impact speed (Hunt-Crossley)
        rig.labels[hidden] = {"coefficient": e}
    elif hidden == "impact_speed_loss":
        rig.rail_n = rng.uniform(0.5, 2.5)
        rig.labels[hidden] = {"rail_friction_n": rig.rail_n}
    elif hidden == "structural_compliance":
        rig.contact_k, rig.contact_n = 10 ** rng.uniform(4.0, 5.0), 1.0
        rig.labels[hidden] = {"stiffness_n_per_m": rig.contact_k}
    elif hidden == "backlash":
        rig.backlash_rad = rng.uniform(0.01, 0.04)
        rig.labels[hidden] = {"backlash_rad": rig.backlash_rad}
    elif hidden == "sensor_delay":
        rig.delay_s = rng.uniform(0.004, 0.015)
        rig.labels[hidden] = {"delay_s": rig.delay_s}
    elif hidden == "quantization":
        rig.counts_per_rev = rng.choice((512, 1024, 2048))
        rig.labels[hidden] = {"step_rad": 2 * math.pi / rig.counts_per_rev}
    conventions = {
        "strike_sign": rig.sign,
        "declares_sign": rng.random() < 0.3,
        "triggered_s": rng.uniform(0.05, 0.2) if rng.random() < 0.4 else None,
        "commands": rng.random() < 0.6,
        "stamp_s": rng.uniform(1.7e9, 2.1e9),
    }
    return rig, conventions


def tip_height(rig: Rig, theta: np.ndarray) -> np.ndarray:
    """The tip's height: a strike pushes it down and turns the arm towards ``rig.sign``."""
    return np.asarray(-rig.sign * rig.arm_m * np.sin(theta))


def simulate(rig: Rig, heights: np.ndarray, restitution: float | None) -> dict[str, np.ndarray]:
    """All drops at once: state (phi, w_m, theta, w_a, y, v) from the release at t = 0."""
    n = heights.size
    # the arm at rest where impedance and the offset balance (friction aside)
    rest = rig.theta_d + rig.offset_nm / rig.k_s
    y0 = tip_height(rig, np.full(n, rest)) + heights
    state = np.stack([np.full(n, rest), np.zeros(n), np.full(n, rest), np.zeros(n), y0,
                      np.zeros(n)])  # fmt: skip
    alpha = np.full(n, rig.contact_alpha)
    if restitution is not None:  # Hunt-Crossley: alpha = 1.5 (1 - e) / impact speed
        alpha = 1.5 * (1 - restitution) / np.sqrt(2 * G * heights)
    two_body = rig.backlash_rad > 0
    j_m = rig.rotor_inertia if two_body else rig.rotor_inertia + rig.arm_inertia

    def rates(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        phi, w_m, theta, w_a, y, v = s
        if not two_body:
            theta, w_a = phi, w_m
        tip = tip_height(rig, theta)
        tip_v = -rig.sign * rig.arm_m * np.cos(theta) * w_a
        depth = tip - y
        touching = depth > 0
        d = np.where(touching, depth, 0.0)
        force = rig.contact_k * d**rig.contact_n * (1 + alpha * (tip_v - v))
        force = np.where(touching, np.maximum(force, 0.0), 0.0)
        on_arm = force * rig.sign * rig.arm_m * np.cos(theta)
        drive = np.clip(rig.k_s * (rig.theta_d - phi), -rig.peak_torque, rig.peak_torque)
        hump = (rig.static - rig.coulomb) * np.exp(-((w_m / rig.stribeck_w) ** 2))
        friction = (rig.coulomb + hump) * np.tanh(w_m / rig.eps_w) + rig.viscous * w_m
        rail = rig.rail_n * np.tanh(v / 0.001)  # Coulomb, smoothed over 1 mm/s
        a_y = -G + (force - rail) / rig.mass_kg
        if two_body:
            gap = rig.backlash_rad / 2
            twist = phi - theta
            wound = np.sign(twist) * np.maximum(np.abs(twist) - gap, 0.0)
            engaged = np.abs(twist) > gap
            coupling = 2e3 * wound + np.where(engaged, 2.0 * (w_m - w_a), 0.0)
            a_m = (drive - friction - coupling) / rig.rotor_inertia
            a_a = (coupling + on_arm + rig.offset_nm) / rig.arm_inertia
        else:
            a_m = (drive - friction + on_arm + rig.offset_nm) / j_m
            a_a = a_m
        return np.stack([w_m, a_m, w_a, a_a, v, a_y]), force

    fall = np.sqrt(2 * heights / G)
    steps = math.ceil((float(fall.max()) + AFTER_CONTACT_S) / DT)
    keep = max(1, round(1 / (DT * 20000.0)))  # stored at 20 kHz, sampled from there
    out = np.empty((steps // keep + 1, 7, n))
    for k in range(steps + 1):
        if k % keep == 0:
            _, force = rates(state)
            out[k // keep, :6] = state
            out[k // keep, 6] = force
        k1, _ = rates(state)
        k2, _ = rates(state + 0.5 * DT * k1)
        k3, _ = rates(state + 0.5 * DT * k2)
        k4, _ = rates(state + DT * k3)
        state = state + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    t = np.arange(out.shape[0]) * DT * keep
    return {"t": t, "phi": out[:, 0], "y": out[:, 4], "force": out[:, 6], "rest": np.full(n, rest)}


def write_campaign(out: Path, seed: int) -> Path:
    """One bag per height under ``out/bags``, labels in ``out/labels.json``."""
    from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: PLC0415
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415

    rig, conv = draw_rig(seed)
    e = rig.labels.get("restitution", {}).get("coefficient")
    heights = np.array(HEIGHTS)
    sim = simulate(rig, heights, e)
    rng = np.random.default_rng(seed)
    store = get_typestore(Stores.ROS2_JAZZY)
    msg = store.types
    base_ns = round(conv["stamp_s"] * 1e9)
    on_arm = []
    for i, height in enumerate(heights):
        t, phi, y, force = sim["t"], sim["phi"][:, i], sim["y"][:, i], sim["force"][:, i]
        contact = float(t[np.argmax(force > 1.0)])
        later = (t > contact + 0.1) & (t < contact + AFTER_CONTACT_S)
        on_arm.append(bool(np.mean(force[later] > 0.5 * rig.mass_kg * G) > 0.5))
        start = -0.1 if conv["triggered_s"] is None else contact - conv["triggered_s"]
        end = contact + AFTER_CONTACT_S - 0.01
        bag = out / "bags" / rig.actuator / f"drop_{i:02d}"
        bag.parent.mkdir(parents=True, exist_ok=True)
        custom = {
            "transparency.trial": "drop_test",
            "transparency.actuator": rig.actuator,
            "transparency.k_s": repr(rig.k_s),
            "transparency.k_d": "0.0",
            "transparency.threshold_rad": "0.1",
            "transparency.shuttle_mass_kg": repr(rig.mass_kg),
            "transparency.arm_length_m": repr(rig.arm_m),
            "transparency.arm_inertia_kgm2": repr(rig.arm_inertia),
            "transparency.drop_height_m": repr(float(height)),
        }
        if conv["declares_sign"]:
            custom["transparency.strike_sign"] = str(rig.sign)

        def ns(time_s: float) -> int:
            return base_ns + round((time_s + 0.1) * 1e9)

        def header(time_s: float) -> Any:
            sec, nanosec = divmod(ns(time_s), 1_000_000_000)
            return msg["std_msgs/msg/Header"](
                stamp=msg["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=""
            )

        writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        try:
            for key, value in custom.items():
                writer.set_custom_data(key, value)
            js = writer.add_connection(
                "/joint_states", "sensor_msgs/msg/JointState", typestore=store
            )
            joint_type = "sensor_msgs/msg/JointState"
            cmd = (
                writer.add_connection("/joint_commands", joint_type, typestore=store)
                if conv["commands"]
                else None
            )
            lc = writer.add_connection(
                "/load_cell", "geometry_msgs/msg/WrenchStamped", typestore=store
            )
            sh = writer.add_connection(
                "/shuttle/height", "geometry_msgs/msg/PointStamped", typestore=store
            )
            records: list[tuple[int, Any, bytes]] = []

            def joint(time_s: float, position: float, effort: float) -> bytes:
                m = msg["sensor_msgs/msg/JointState"](
                    header=header(time_s), name=["arm_joint"], position=np.array([position]),
                    velocity=np.array([]), effort=np.array([effort]),
                )  # fmt: skip
                return bytes(store.serialize_cdr(m, "sensor_msgs/msg/JointState"))

            if cmd is not None:
                records.append((ns(start), cmd, joint(start, rig.theta_d, 0.0)))
            step = 2 * math.pi / rig.counts_per_rev
            for ts in np.arange(max(start, 0.0), end, 1 / rig.encoder_hz):
                # the reading taken at ts - delay, stamped ts (a late encoder)
                true = float(np.interp(ts - rig.delay_s, t, phi)) if ts >= rig.delay_s else phi[0]
                reading = round(true / step) * step
                effort = float(np.clip(rig.k_s * (rig.theta_d - true), -rig.peak_torque,
                                       rig.peak_torque))  # fmt: skip
                records.append((ns(ts), js, joint(ts, reading, effort)))
            if start < 0:  # the hold before the release: the arm at rest
                for ts in np.arange(start, 0.0, 1 / rig.encoder_hz):
                    reading = round(float(phi[0]) / step) * step
                    records.append(
                        (ns(ts), js, joint(ts, reading, rig.k_s * (rig.theta_d - phi[0])))
                    )
            rest_tip = float(tip_height(rig, np.array([sim["rest"][i]]))[0])
            for ts in np.arange(start, end, 1 / rig.daq_hz):
                f = float(np.interp(ts, t, force)) if ts >= 0 else 0.0
                h = float(np.interp(ts, t, y)) if ts >= 0 else float(y[0])
                f += rng.normal(0, rig.force_noise_n)
                h = h - rest_tip + rng.normal(0, rig.height_noise_m)
                wrench = msg["geometry_msgs/msg/WrenchStamped"](
                    header=header(ts),
                    wrench=msg["geometry_msgs/msg/Wrench"](
                        force=msg["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=f),
                        torque=msg["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    ),
                )
                point = msg["geometry_msgs/msg/PointStamped"](
                    header=header(ts), point=msg["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=h)
                )
                records.append((ns(ts), lc, bytes(store.serialize_cdr(wrench, lc.msgtype))))
                records.append((ns(ts), sh, bytes(store.serialize_cdr(point, sh.msgtype))))
            for stamp, conn, data in sorted(records, key=lambda r: r[0]):
                writer.write(conn, stamp, data)
        finally:
            writer.close()
    labels = {
        "seed": seed,
        "actuator": rig.actuator,
        "hidden": rig.labels,
        "weight_on_arm": sum(on_arm) >= len(on_arm) / 2,
        "conventions": conv,
    }
    (out / "labels.json").write_text(json.dumps(labels, indent=1))
    return out


def analyse(seed: int) -> dict[str, Any]:
    from transparency_ros.analysis.discrepancy.discover import Discoverer  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.drop import (  # noqa: PLC0415
        DropProblem,
        load_drop_nominal,
        load_drop_trial,
    )
    from transparency_ros.bag.reader import find_bags  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        started = time.perf_counter()
        out = write_campaign(Path(tmp) / str(seed), seed)
        made = time.perf_counter() - started
        labels = json.loads((out / "labels.json").read_text())
        started = time.perf_counter()
        try:
            trials = [load_drop_trial(b) for b in find_bags([str(out / "bags")])]
            problem = DropProblem(trials, load_drop_nominal(None, trials))
            report = Discoverer(problem).run()
            found = {f.effect: f.parameters for f in report.findings}
            notes, unexplained, error = report.notes, bool(report.unexplained), None
            rmse = (report.heldout_rmse_nominal, report.final_heldout_rmse)
        except Exception as err:  # noqa: BLE001 - a failure is a result here, with its reason
            found, notes, unexplained, error, rmse = (
                {},
                [],
                False,
                f"{type(err).__name__}: {err}",
                None,
            )
    return {
        "seed": seed, "labels": labels, "found": found, "notes": notes,
        "unexplained": unexplained, "error": error, "rmse": rmse,
        "seconds": time.perf_counter() - started, "generate_s": made,
    }  # fmt: skip


def score(rows: list[dict[str, Any]]) -> list[str]:
    single = [r for r in rows if r["labels"]["hidden"]]
    free = [r for r in rows if not r["labels"]["hidden"]]
    recalled = [r for r in single if next(iter(r["labels"]["hidden"])) in r["found"]]
    weight = [r for r in rows if r["labels"]["weight_on_arm"]]
    weight_named = [r for r in weight if "payload_gravity" in r["found"]]

    def allowed(r: dict[str, Any]) -> set[str]:
        return set(r["labels"]["hidden"]) | (
            {"payload_gravity"} if r["labels"]["weight_on_arm"] else set()
        )

    false_free = sum(len(set(r["found"]) - allowed(r)) for r in free)
    names = sum(len(r["found"]) for r in rows)
    right = sum(len(set(r["found"]) & allowed(r)) for r in rows)
    failed = [r for r in rows if r["error"]]
    times = [r["seconds"] for r in rows]
    weight_row = f"{len(weight_named)}/{len(weight)}"
    return [
        f"| single-effect recall | {len(recalled)}/{len(single)} |",
        f"| false findings on campaigns with nothing hidden | {false_free} in {len(free)} |",
        f"| the shuttle's weight named where it rests on the arm | {weight_row} |",
        f"| precision of named effects (the resting weight counts as right) | {right}/{names} |",
        f"| campaigns the tool could not read | {len(failed)} |",
        f"| run time per campaign [s], median / max | {np.median(times):.1f} / {max(times):.1f} |",
    ]


def main(argv: list[str] | None = None) -> int:
    from _results import write_results  # noqa: PLC0415

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="300:330", help="first:last+1")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)
    first, last = (int(x) for x in args.seeds.split(":"))
    started = time.perf_counter()
    with Pool(args.jobs) as pool:
        rows = []
        for row in pool.imap(analyse, range(first, last)):
            rows.append(row)
            lab = row["labels"]
            print(f"independent {row['seed']} {lab['actuator']} hidden {list(lab['hidden'])} "
                  f"weight on arm {lab['weight_on_arm']} {lab['conventions']} -> found "
                  f"{list(row['found'])}{' unexplained' if row['unexplained'] else ''}"
                  f"{' ERROR ' + row['error'] if row['error'] else ''} ({row['seconds']:.1f} s)",
                  file=sys.stderr)  # fmt: skip
    lines = [
        f"Seeds {first}-{last - 1}: {len(rows)} campaigns of the independent rig "
        "(benchmarks/independent_rig.py), the tool blind",
        "",
        "| measure | this tool |",
        "|---|---|",
        *score(rows),
        "",
        f"{args.jobs} processes, {time.perf_counter() - started:.0f} s in all "
        "(`.venv/bin/python benchmarks/independent_rig.py`).",
    ]
    write_results(args.out, "independent_rig", lines, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
