"""``transparency import-csv`` and ``transparency discrepancy`` (1-DoF torque-driven)."""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path
from typing import Any

import numpy as np

from transparency_ros.core import strict_json
from transparency_ros.core.errors import ConfigError

TRIAL_KIND = "torque_driven"
DROP_KIND = "drop_test"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "import-csv",
        help="turn column data (time, position, velocity, torque) into rosbag2 MCAP bags",
        description=(
            "One bag per CSV file (plain or .xz), stamped with the time column. One joint "
            "(--joint): /joint_states (sensor_msgs/msg/JointState) with position [rad], "
            "velocity [rad/s] and effort = torque [N m], custom_data transparency.trial = "
            "torque_driven, for `transparency discrepancy`. Several joints (--joints): "
            "/joint_states (position, velocity; effort = the --measured torque where the file "
            "has it), /joint_commands (effort = the commanded torque; position = --desired "
            "where the file has it) and /true_external_effort (effort = --labels where the file "
            "has it), transparency.trial = robot, for `transparency calibrate` and `detect`. "
            "custom_data transparency.source = the file."
        ),
    )
    p.add_argument("csv", nargs="+")
    p.add_argument("--out", required=True, help="directory for the bags")
    p.add_argument(
        "--columns",
        help="one joint: names of the time, position, velocity and torque columns, in that "
        "order (default time,position,velocity,torque); several joints: patterns, {} is the "
        "joint's number (default time=time,position=pos_meas{},velocity=vel_meas{},"
        "torque=tau_con{}, the DFKI double pendulum's)",
    )
    p.add_argument("--joint", default="joint", help="joint name in the bag (one joint)")
    p.add_argument(
        "--joints",
        metavar="NAMES",
        help="the joints of the columns numbered 1, 2, ... (comma-separated): a robot's bag",
    )
    p.add_argument("--measured", default="tau_meas{}", help="several joints: measured torque")
    p.add_argument("--desired", default="pos_des{}", help="several joints: desired position")
    p.add_argument("--labels", default="tau_pert{}", help="several joints: true external torque")
    p.set_defaults(func=run_import)

    d = subparsers.add_parser(
        "discrepancy",
        help="locate where a model and recordings differ, name and model the missing physics",
        description=(
            "Simulate the nominal model for every trial, fit candidate effects on some trials, "
            "keep those that improve the held-out trials, report where they act and what is "
            "left unexplained. 1-DoF torque-driven recordings (bags with /joint_states: "
            "position, velocity, effort = torque) are simulated in windows; drop-test bags "
            "(transparency.trial = drop_test, one actuator per run) against eq. (2) with "
            "Table 1. A robot's runs (--urdf: CSV or bags of several joints) are judged on the "
            "joints' torque balance against the URDF's model, whole runs held out."
        ),
    )
    d.add_argument(
        "bags",
        nargs="+",
        metavar="RECORDING",
        help="bags or directories of bags; with --urdf also CSV files (.csv, .csv.xz)",
    )
    d.add_argument(
        "--urdf",
        help="a robot: its URDF; the recordings are its runs (CSV as `detect` reads them, or "
        "bags with /joint_states and /joint_commands efforts), judged on the joints' torque "
        "balance, every third run held out",
    )
    d.add_argument(
        "--joints",
        help="with --urdf: the URDF joints of the CSV's columns 1, 2, ... (default: the URDF's "
        "movable joints in order)",
    )
    d.add_argument(
        "--columns",
        default="time=time,position=pos_meas{},velocity=vel_meas{},torque=tau_con{}",
        help="with --urdf: CSV column patterns, {} is the joint's number (default: the DFKI "
        "double pendulum's)",
    )
    d.add_argument(
        "--nominal",
        metavar="SPEC.yaml",
        help="torque-driven (required): nominal terms (inertia_kgm2, viscous_nms_per_rad, "
        "coulomb_nm, gravity_nm, gravity_offset_rad) or a DFKI pendulum parameter file; "
        "drop tests (optional): overrides of reflected_inertia_kgm2, viscous_nms_per_rad, "
        "coulomb_nm; robots (--urdf, optional): the URDF's terms overridden (gravity_mps2, "
        "joints: {NAME: {armature_kgm2, viscous_nms_per_rad, coulomb_nm, effort_limit_nm}}, "
        "links: {NAME: {mass_kg, com_m, inertia_com_kgm2}}) or a DFKI double-pendulum "
        "parameter file",
    )
    d.add_argument("--window", type=float, default=0.1, metavar="S", help="window length [s]")
    d.add_argument("--json", action="store_true")
    d.add_argument("--report", metavar="DIR", help="write plots and a summary table here")
    d.set_defaults(func=run_discrepancy)


def run_import(args: argparse.Namespace) -> int:
    from transparency_ros.analysis.robot_data import read_text  # noqa: PLC0415
    from transparency_ros.bag.writer import (  # noqa: PLC0415
        BagWriter,
        check_writable,
        message_types,
        time_msg,
    )

    if args.joints:
        return _import_robot(args)
    names = [c.strip() for c in (args.columns or "time,position,velocity,torque").split(",")]
    if len(names) != 4:
        raise ConfigError("--columns needs four names: time, position, velocity, torque")
    runs = [(path, _single_joint_csv(path, read_text(path), names)) for path in map(Path, args.csv)]
    out = Path(args.out)
    check_writable(out)
    types = message_types()
    for path, (t, q, qd, tau) in runs:  # every file read and checked before a bag is written
        bag = out / bag_name(path)
        with BagWriter(
            bag, {"transparency.trial": TRIAL_KIND, "transparency.source": path.name}
        ) as writer:
            writer.add("/joint_states", "sensor_msgs/msg/JointState")
            for ti, qi, vi, ei in zip(t, q, qd, tau, strict=True):
                ns = round(float(ti) * 1e9)
                stamp = time_msg(ns)
                msg = types["sensor_msgs/msg/JointState"](
                    header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                    name=[args.joint],
                    position=np.array([qi]),
                    velocity=np.array([vi]),
                    effort=np.array([ei]),
                )
                writer.write_message("/joint_states", ns, msg)
        print(f"{bag}  ({t.size} samples)")
    return 0


def _single_joint_csv(path: Path, text: str, names: list[str]) -> list[Any]:
    """The time, position, velocity and torque columns of a one-joint CSV, checked: at least
    two data rows, finite numbers, time increasing."""
    from transparency_ros.analysis.robot_data import check_time  # noqa: PLC0415

    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise ConfigError(f"{path}: empty file (no header)")
    header = [h.strip() for h in lines[0].split(",")]
    missing = [n for n in names if n not in header]
    if missing:
        raise ConfigError(f"{path}: no column(s) {missing}; the header has {header}")
    rows = sum(1 for line in lines[1:] if line.strip())
    if rows < 2:
        raise ConfigError(f"{path}: {rows} data rows; at least 2 are needed")
    try:
        data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)
    except ValueError as err:
        raise ConfigError(f"{path}: cannot read CSV: {err}") from err
    if data.shape[1] != len(header):
        raise ConfigError(f"{path}: rows of {data.shape[1]} values under {len(header)} columns")
    cols = [data[:, header.index(n)] for n in names]
    if not all(np.isfinite(c).all() for c in cols):
        raise ConfigError(f"{path}: NaN or inf in the data")
    check_time(path, names[0], cols[0])
    return cols


def bag_name(path: Path) -> str:
    """The bag of ``path``: its name without .xz and .csv (``run_01.csv.xz`` -> ``run_01``)."""
    name = path.name
    for suffix in (".xz", ".csv"):
        name = name.removesuffix(suffix)
    return name


def _import_robot(args: argparse.Namespace) -> int:
    """Every file read (and checked) before any bag is written."""
    from transparency_ros.analysis.robot_data import (  # noqa: PLC0415
        Columns,
        read_joint_csv,
        write_joint_bag,
    )
    from transparency_ros.bag.writer import check_writable  # noqa: PLC0415

    joints = [j.strip() for j in args.joints.split(",")]
    if not all(joints) or len(set(joints)) != len(joints):
        raise ConfigError(f"--joints: {args.joints!r} needs distinct, non-empty names")
    default = "time=time,position=pos_meas{},velocity=vel_meas{},torque=tau_con{}"
    columns = Columns.parse(
        args.columns or default, label=args.labels, desired=args.desired, measured=args.measured
    )
    out = Path(args.out)
    bags = [out / bag_name(Path(f)) for f in args.csv]
    taken = [str(b) for b in bags if b.exists()]
    if taken or len(set(bags)) != len(bags):
        raise ConfigError(f"--out: bag(s) {taken or bags} exist already or twice; not overwritten")
    recordings = [read_joint_csv(f, joints, columns) for f in args.csv]
    check_writable(out)
    for path, bag, rec in zip(args.csv, bags, recordings, strict=True):
        for note in rec.notes:
            print(f"note: {note}", file=sys.stderr)
        write_joint_bag(bag, rec, Path(path).name)
        extra = [
            name
            for name, a in (("measured", rec.measured), ("desired", rec.desired),
                            ("labels", rec.label))
            if a is not None
        ]  # fmt: skip
        print(
            f"{bag}  ({rec.stamps_ns.size} samples of {len(joints)} joints"
            + (f"; with {', '.join(extra)})" if extra else ")")
        )
    return 0


def run_discrepancy(args: argparse.Namespace) -> int:
    from transparency_ros.analysis.discrepancy.discover import Discoverer  # noqa: PLC0415

    if args.urdf:
        return _run_robot(args)
    problem = _problem(args)
    report = Discoverer(
        problem, progress=lambda text: print(text, file=sys.stderr, flush=True)
    ).run()
    if args.report:
        from transparency_ros.analysis.discrepancy.report import write_report  # noqa: PLC0415

        for path in write_report(Path(args.report), problem, report):
            print(f"wrote {path}", file=sys.stderr)
    if args.json:
        strict_json.dump(report.as_dict(), sys.stdout)
        return 0
    from transparency_ros.analysis.discrepancy.findings import parameters_text  # noqa: PLC0415

    print(f"nominal: {', '.join(f'{k} {v:g}' for k, v in report.nominal.items())}")
    print(f"held-out trials: {', '.join(report.split['heldout'])}")
    for note in report.notes:
        print(f"note: {note}")
    print(f"held-out simulation RMSE, nominal: {report.heldout_rmse_nominal:.4g} rad")
    for f in report.findings:
        params = parameters_text(f)
        print(
            f"found {f.effect}: {params}; where: {f.where['phase']} "
            f"({f.where['trial']} {f.where['window_s']} s); {f.evidence}"
        )
    for u in report.unexplained:
        print(f"unexplained: {u['looks_like']}")
    if not report.findings and not report.unexplained:
        print("no significant discrepancy: the nominal model explains the recordings")
    print(f"final held-out RMSE: {report.final_heldout_rmse:.4g} rad ({report.seconds:.1f} s)")
    return 0


def _run_robot(args: argparse.Namespace) -> int:
    """The discrepancy tool on a robot's runs (``--urdf``)."""
    from transparency_ros.analysis.discrepancy.discover import Discoverer  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.robot import RobotProblem, robot_result  # noqa: PLC0415
    from transparency_ros.commands.detect import read_recordings, robot_model  # noqa: PLC0415

    model = robot_model(args)  # (with --nominal's terms)
    problem = RobotProblem(model, read_recordings(args, model, args.bags))
    report = Discoverer(
        problem, progress=lambda text: print(text, file=sys.stderr, flush=True)
    ).run()
    result = robot_result(problem, report)
    if args.report:
        from transparency_ros.analysis.discrepancy.report import write_report  # noqa: PLC0415

        for path in write_report(Path(args.report), problem, report):
            print(f"wrote {path}", file=sys.stderr)
    if args.json:
        strict_json.dump(result, sys.stdout)
        return 0
    print(f"held-out runs: {', '.join(report.split['heldout'])}")
    for note in report.notes:
        print(f"note: {note}")
    for f in result["findings"]:
        values = ", ".join(f"{k} {v:.4g}" for k, v in f["parameters"].items())
        print(
            f"found {f['effect']} on {f['joint'] or 'the whole robot'}: {values}; {f['evidence']}"
        )
    for u in report.unexplained:
        print(f"unexplained: {u['looks_like']}")
    window = result["open_loop"]["window_s"]
    for joint, (before, after) in result["heldout_rms_nm"].items():
        sim_before, sim_after = result["heldout_open_loop_rad"][joint]
        print(f"{joint}: held-out torque residual {before:.3g} -> {after:.3g} N m RMS; "
              f"open-loop error over {window:g} s windows {sim_before:.3g} -> {sim_after:.3g} "
              "rad RMS")  # fmt: skip
    if result["open_loop"]["diverged_before"] or result["open_loop"]["diverged_after"]:
        o = result["open_loop"]
        print(f"note: open-loop windows that left the motion (counted at pi rad): "
              f"{o['diverged_before']} -> {o['diverged_after']} of {o['windows']}")  # fmt: skip
    return 0


def _problem(args: argparse.Namespace) -> Any:
    """The problem of the bags' kind: all bags of one run are of one kind."""
    from transparency_ros.analysis.discrepancy.model import Trial, load_nominal  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.torque_driven import (  # noqa: PLC0415
        TorqueDrivenProblem,
    )
    from transparency_ros.bag.reader import find_bags, joint_series, open_bag  # noqa: PLC0415

    bags = find_bags(args.bags)
    kinds: dict[str, list[Path]] = {}
    for bag_path in bags:
        with open_bag(bag_path) as bag:
            kind = bag.custom_data.get("transparency.trial", TRIAL_KIND)
        kinds.setdefault(kind, []).append(bag_path)
    if len(kinds) > 1:
        listed = "; ".join(f"{k}: {', '.join(p.name for p in v[:3])}" for k, v in kinds.items())
        raise ConfigError(f"the bags are of different kinds ({listed}); analyse one kind at a time")
    kind = next(iter(kinds))
    if kind == DROP_KIND:
        from transparency_ros.analysis.discrepancy.drop import (  # noqa: PLC0415
            DropProblem,
            load_drop_nominal,
            load_drop_trial,
        )

        drops = [load_drop_trial(b) for b in bags]
        return DropProblem(drops, load_drop_nominal(args.nominal, drops))
    if kind != TRIAL_KIND:
        raise ConfigError(
            f"{kinds[kind][0]}: transparency.trial = {kind!r}; the tool reads "
            f"{TRIAL_KIND!r} and {DROP_KIND!r} recordings"
        )
    if args.nominal is None:
        raise ConfigError("torque-driven recordings need --nominal SPEC.yaml")
    model = load_nominal(args.nominal)
    trials = []
    for bag_path in bags:
        with open_bag(bag_path) as bag:
            s = joint_series(bag, "/joint_states")
        trials.append(
            Trial(bag_path.name, s.seconds(int(s.stamp_ns[0])), s.position, s.velocity, s.effort)
        )
    return TorqueDrivenProblem(model, trials, window_s=args.window)
