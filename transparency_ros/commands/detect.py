"""``transparency calibrate`` and ``transparency detect``: contact detection on a robot's
recordings with a model from its URDF (see docs/robots.md)."""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path
from typing import Any

import numpy as np

from transparency_ros.core import strict_json
from transparency_ros.core.errors import ConfigError

METHODS = ("momentum_observer", "textbook", "position_error")


def add_recording_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "recordings",
        nargs="+",
        metavar="RECORDING",
        help="CSV files (.csv, .csv.xz) or rosbag2 bags (/joint_states, /joint_commands effort)",
    )
    p.add_argument("--urdf", required=True, help="the robot's URDF file")
    p.add_argument(
        "--joints",
        help="the URDF joints of the CSV's columns 1, 2, ... (comma-separated; default: the "
        "URDF's movable joints in order)",
    )
    p.add_argument(
        "--columns",
        default="time=time,position=pos_meas{},velocity=vel_meas{},torque=tau_con{}",
        help="column patterns, {} is the joint's number (default: the DFKI double pendulum's)",
    )
    p.add_argument("--gain", type=float, default=20.0, help="observer gain K_o [1/s]")


def register(subparsers: Any) -> None:
    c = subparsers.add_parser(
        "calibrate",
        help="learn what a robot's model misses from recordings without contact",
        description=(
            "Fit the command delay, the links' inertial parameters, each joint's armature, "
            "friction and torque offset, and thresholds that grow with speed, from recordings "
            "in which nothing touched the robot; write them as a YAML for `transparency detect "
            "--calibration`."
        ),
    )
    add_recording_arguments(c)
    c.add_argument("--out", required=True, help="the calibration YAML to write")
    c.set_defaults(func=run_calibrate)

    d = subparsers.add_parser(
        "detect",
        help="detect contacts in a robot's recordings and score them against labels",
        description=(
            "Run a contact detector over recordings as the estimator node would: the "
            "momentum observer with a calibration, the textbook observer (the URDF as it is) "
            "or eq. (1)'s position error (thresholds from --clean recordings). With --labels, "
            "score it per joint: pulses found, false alarms per minute, delay."
        ),
    )
    add_recording_arguments(d)
    d.add_argument("--method", choices=METHODS, default="momentum_observer")
    d.add_argument("--calibration", help="calibration YAML (momentum_observer)")
    d.add_argument(
        "--clean",
        nargs="+",
        default=[],
        metavar="RECORDING",
        help="recordings without contact: thresholds just above their largest residual "
        "(textbook, position_error)",
    )
    d.add_argument(
        "--labels",
        metavar="PATTERN",
        help="column of the true external torque per joint, e.g. tau_pert{}; in bags the "
        "topic /true_external_effort (as import-csv --joints writes it), or the topic given "
        "if it starts with /",
    )
    d.add_argument(
        "--desired",
        default="pos_des{}",
        help="desired-position column pattern (in bags: /joint_commands' positions)",
    )
    d.add_argument("--report", metavar="DIR", help="write a plot per recording here")
    d.add_argument(
        "--json",
        action="store_true",
        help="print as JSON: per recording and joint the contacts (onset, release, peak "
        "residual); with --labels the scores per joint and the missed pulses",
    )
    d.set_defaults(func=run_detect)


def robot_model(args: argparse.Namespace) -> Any:
    """The robot's model from ``--urdf``, with ``--nominal``'s terms where the command has it
    (discrepancy, assay); its notes on stderr."""
    from transparency_ros.core.robot_model import RobotModel  # noqa: PLC0415

    model = RobotModel.from_urdf(args.urdf)
    if getattr(args, "nominal", None):
        from transparency_ros.analysis.robot_nominal import with_nominal  # noqa: PLC0415

        model = with_nominal(model, args.nominal)
    for note in model.notes:
        print(f"note: {note}", file=sys.stderr)
    return model


def read_recordings(
    args: argparse.Namespace, model: Any, paths: list[str], labels: str | None = None
) -> list[Any]:
    """The recordings in ``paths`` (CSV or bags, globs expanded), in the model's joint order."""
    from transparency_ros.analysis.robot_data import (  # noqa: PLC0415
        LABEL_TOPIC,
        Columns,
        read_joint_bag,
        read_joint_csv,
    )
    from transparency_ros.analysis.robot_detect import in_model_order  # noqa: PLC0415

    joints = args.joints.split(",") if args.joints else list(model.joint_names)
    columns = Columns.parse(args.columns, label=labels, desired=getattr(args, "desired", None))
    # in a bag the labels are a topic: the one given, or the one import-csv writes
    topic = None if labels is None else (labels if labels.startswith("/") else LABEL_TOPIC)
    files = [f for p in paths for f in (sorted(glob.glob(p)) or [p])]
    recordings = [
        read_joint_csv(f, joints, columns, exact=not args.joints)
        if ".csv" in Path(f).name
        else read_joint_bag(f, joints, topic)
        for f in files
    ]
    if labels is not None and recordings and all(r.label is None for r in recordings):
        column = columns.label.format(1) if columns.label else labels
        raise ConfigError(
            f"--labels {labels}: no recording has them (a CSV's column {column!r}, a bag's "
            f"topic {topic})"
        )
    for rec in recordings:
        for note in rec.notes:
            print(f"note: {note}", file=sys.stderr)
    return [in_model_order(model, r) for r in recordings]


def run_calibrate(args: argparse.Namespace) -> int:
    from transparency_ros.analysis.robot_calibration import calibrate  # noqa: PLC0415

    model = robot_model(args)
    recordings = read_recordings(args, model, args.recordings)
    cal = calibrate(model, recordings, args.gain, progress=lambda m: print(m, file=sys.stderr))
    cal.save(args.out)
    print(
        f"calibrated {cal.robot} ({', '.join(cal.joints)}) on {len(recordings)} "
        f"recording{'s' if len(recordings) > 1 else ''}: "
        f"command delay {cal.command_delay_s * 1e3:.0f} ms, torque residual "
        f"{cal.torque_rms_nm:.3f} N m RMS, mass matrix positive definite at "
        f"{cal.mass_matrix_positive_share:.0%} of the configurations; written to {args.out}"
    )
    if cal.mass_matrix_positive_share < 1.0:
        print(
            "note: the calibration fits the torque balance, not the physics (see docs/robots.md):"
            " the observer uses M(q) only through p = M(q) q' and never inverts it, but do not "
            "simulate with this model",
            file=sys.stderr,
        )
    return 0


def run_detect(args: argparse.Namespace) -> int:
    from transparency_ros.analysis import robot_detect as rd  # noqa: PLC0415
    from transparency_ros.core.robot_calibration import Calibration  # noqa: PLC0415

    model = robot_model(args)
    recordings = read_recordings(args, model, args.recordings, args.labels)
    if args.method == "momentum_observer":
        if not args.calibration:
            raise ConfigError("--method momentum_observer needs --calibration (see calibrate)")
        cal = Calibration.load(args.calibration)
        detections = [rd.calibrated(model, cal, r) for r in recordings]
    else:
        if not args.clean:
            raise ConfigError(f"--method {args.method} needs --clean recordings for thresholds")
        clean = read_recordings(args, model, args.clean)

        def signal(r: Any) -> Any:
            if args.method == "textbook":
                return rd.textbook_residual(model, r, args.gain)
            return rd.position_error(r)

        thresholds = rd.constant_thresholds([signal(r) for r in clean])
        detections = [rd.with_threshold(r, signal(r), thresholds) for r in recordings]
    if args.report:
        from transparency_ros.analysis.robot_plots import plot_detection  # noqa: PLC0415

        for det, rec in zip(detections, recordings, strict=True):
            print(f"wrote {plot_detection(Path(args.report), det, rec)}")
    # joint -> (score, recall by chance); without labels there is nothing to score: onsets
    # are not false alarms
    scores = {
        joint: (rd.score(detections, recordings, joint=j),
                rd.by_chance(detections, recordings, joint=j).recall)
        for j, joint in enumerate(model.joint_names)
    } if args.labels else {}  # fmt: skip
    if args.json:
        strict_json.dump(_report(args, detections, recordings, scores), sys.stdout)
        return 0
    for det in detections:
        for joint, onsets in zip(det.joints, det.onsets_s, strict=True):
            times = ", ".join(f"{t:.3f}" for t in onsets) or "none"
            print(f"{det.recording} {joint}: contact onsets at [s] {times}")
    for joint, (s, chance) in scores.items():
        print(
            f"{joint}: {s.found}/{s.pulses} pulses found, {s.false_alarms} false alarms "
            f"({s.alarms_per_minute:.1f} per minute), delay median "
            f"{_ms(s.delay_s(50))}, p90 {_ms(s.delay_s(90))}; "
            f"{chance:.0%} of the pulses would be found by chance (the same onsets "
            "against the labels moved in time)"
        )
    return 0


def _ms(seconds: float) -> str:
    return "n/a" if np.isnan(seconds) else f"{seconds * 1e3:.0f} ms"


def _report(
    args: argparse.Namespace,
    detections: list[Any],
    recordings: list[Any],
    scores: dict[str, tuple[Any, float]],
) -> dict[str, Any]:
    """``detect --json``: per recording and joint the contacts (onset and release stamps [s],
    the peak residual); with labels, per joint the scores, the missed pulses as data."""
    from transparency_ros.analysis import robot_detect as rd  # noqa: PLC0415

    per_recording = []
    for det, rec in zip(detections, recordings, strict=True):
        joints = {}
        for joint, found in zip(det.joints, rd.episodes(det), strict=True):
            joints[joint] = {"contacts": [vars(e) for e in found]}
        per_recording.append({"recording": det.recording, "duration_s": rec.duration_s,
                              "labelled": rec.label is not None, "joints": joints})  # fmt: skip
    return {
        "method": args.method,
        "residual_unit": "rad" if args.method == "position_error" else "N m",
        "recordings": per_recording,
        "scores": {
            j: {**_as_dict(s), "recall_by_chance": chance} for j, (s, chance) in scores.items()
        } if args.labels else None,
    }  # fmt: skip


def _as_dict(s: Any) -> dict[str, Any]:
    return {
        "pulses": s.pulses, "found": s.found, "recall": s.recall,
        "false_alarms": s.false_alarms, "alarms_per_minute": s.alarms_per_minute,
        "delay_median_s": s.delay_s(50), "delay_p90_s": s.delay_s(90),
        "judged_share": s.judged_share, "missed": s.missed,
        "minutes": s.minutes,
    }  # fmt: skip
