"""``transparency assay``: a robot's contact detectors, their minimum detectable external torque
per joint, measured on its runs without contact (see docs/robots.md)."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from transparency_ros.commands.detect import add_recording_arguments, read_recordings, robot_model
from transparency_ros.core import strict_json
from transparency_ros.core.errors import ConfigError

DETECTORS = ("calibrated", "named", "textbook")


def register(subparsers: Any) -> None:
    a = subparsers.add_parser(
        "assay",
        help="a robot's minimum detectable external torque per joint, from runs without contact",
        description=(
            "The sensitivity assay: add rectangular pulses to the recorded command of runs "
            "without contact (the same motion with an external torque and the motor applying "
            "the rest), and find per joint the smallest pulse the detector finds in --recall of "
            "the cases at its own thresholds, scaled to --alarms-per-minute false alarms on the "
            "same runs without pulses. The runs are split in --folds: each fold's runs are "
            "assayed with the calibration (and the textbook observer's thresholds) made on the "
            "other folds; with --calibration every run is assayed with that one."
        ),
    )
    add_recording_arguments(a)
    a.add_argument("--calibration", help="a calibration YAML made on other runs (see calibrate)")
    a.add_argument(
        "--nominal",
        metavar="SPEC.yaml",
        help="start from another model than the URDF's as it is (as discrepancy --nominal: a "
        "file of overrides or a DFKI double-pendulum parameter file)",
    )
    a.add_argument("--folds", type=int, default=3, help="folds by run (default 3)")
    a.add_argument(
        "--detectors",
        default=",".join(DETECTORS),
        help=f"comma-separated, of {', '.join(DETECTORS)} (default all): the calibrated "
        "observer (as calibrate makes it), the observer on the URDF with what the discrepancy "
        "tool names on the fold's other runs, the textbook observer (the URDF as it is)",
    )
    a.add_argument("--widths", default="0.05,0.1", help="pulse lengths, shortest,longest [s]")
    a.add_argument("--spacing", type=float, default=1.0, help="one pulse per joint per this [s]")
    a.add_argument("--placements", type=int, default=2, help="pulse trains per run")
    a.add_argument("--recall", type=float, default=0.9, help="share of pulses to find")
    a.add_argument("--alarms-per-minute", type=float, default=1.0, help="false alarms allowed")
    a.add_argument("--seed", type=int, default=0, help="of the pulses' places, lengths, signs")
    a.add_argument("--json", action="store_true", help="print the results as JSON")
    a.set_defaults(func=run)


def _settings(args: argparse.Namespace) -> Any:
    from transparency_ros.analysis.robot_assay import AssaySettings  # noqa: PLC0415

    try:
        lo, hi = (float(x) for x in args.widths.split(","))
    except ValueError:
        raise ConfigError(
            f"--widths {args.widths!r}: two lengths in seconds, e.g. 0.05,0.1"
        ) from None
    return AssaySettings((lo, hi), args.spacing, args.placements, args.recall,
                         args.alarms_per_minute, args.seed)  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from transparency_ros.analysis import robot_assay as ra  # noqa: PLC0415
    from transparency_ros.analysis.robot_calibration import calibrate  # noqa: PLC0415
    from transparency_ros.core.robot_calibration import Calibration, effort_limit  # noqa: PLC0415

    detectors = [d.strip() for d in args.detectors.split(",") if d.strip()]
    unknown = sorted(set(detectors) - set(DETECTORS))
    if unknown or not detectors:
        raise ConfigError(f"--detectors {args.detectors!r}: choose from {', '.join(DETECTORS)}")
    settings = _settings(args)

    def say(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    model = robot_model(args)  # (with --nominal's terms)
    runs = read_recordings(args, model, args.recordings)
    given = Calibration.load(args.calibration) if args.calibration else None
    if given is not None:
        given.model(model)  # a calibration of another robot: one clear line

    cases: dict[str, list[Any]] = {d: [] for d in detectors}
    for f, (train, held) in enumerate(ra.folds(runs, args.folds)):
        fit = [runs[i] for i in train]
        if "calibrated" in cases:
            if given is None:
                say(f"fold {f + 1}/{args.folds}: calibrating on {len(fit)} runs ...")
            cal = given or calibrate(model, fit, args.gain)
            cases["calibrated"] += [(ra.calibrated_detector(model, cal), runs[i]) for i in held]
        if "named" in cases:
            fitted = ra.named_effects(model, fit)
            names = ", ".join(f"{e.name} {_values(e, p)}" for e, p in fitted) or "nothing"
            say(f"fold {f + 1}/{args.folds}: the discrepancy tool names {names}")
            named = ra.named_detector(model, fitted, fit, args.gain)
            cases["named"] += [(named, runs[i]) for i in held]
        if "textbook" in cases:
            tb = ra.textbook_detector(model, args.gain, fit)
            cases["textbook"] += [(tb, runs[i]) for i in held]
    results = {}
    for name, held_out in cases.items():
        say(f"{name}: assaying {len(held_out)} runs ...")
        results[name] = ra.assay(held_out, settings, effort_limit(model), progress=say)
    if args.json:
        strict_json.dump(_as_json(args, settings, runs, results), sys.stdout)
        return 0
    minutes = sum(r.duration_s for r in runs) / 60
    print(
        f"sensitivity assay on {len(runs)} runs without contact ({minutes:.2f} min), "
        f"{'one calibration given' if given else f'{args.folds} folds'}: pulses of "
        f"{settings.widths_s[0] * 1e3:.0f}-{settings.widths_s[1] * 1e3:.0f} ms, "
        f"found in >= {settings.recall:.0%} of cases at <= {settings.alarms_per_minute:g} "
        "false alarms per minute"
    )
    for name, per_joint in results.items():
        for s in per_joint:
            print(f"{name} {s.joint}: {_line(s)}")
    return 0


def _values(effect: Any, p: Any) -> str:
    return ", ".join(f"{n} {v:.3g}" for n, v in zip(effect.param_names, p, strict=True))


def _line(s: Any) -> str:
    at = (f"threshold {s.threshold_nm:.3g} N m (median; its own x{s.threshold_scale:.3g}, "
          f"{s.alarms_per_minute:.2f} false alarms per minute), {s.pulses} pulses per "
          "amplitude")  # fmt: skip
    if s.min_torque_nm is None:
        return (f"not reached: at {s.largest_tried_nm:.3g} N m (the most tried) "
                f"{s.recall:.0%} found; {at}")  # fmt: skip
    delay = "n/a" if math.isnan(s.delay_median_s) else f"{s.delay_median_s * 1e3:.0f} ms"
    return (f"minimum detectable torque {s.min_torque_nm:.3g} N m ({s.recall:.0%} found, "
            f"median delay {delay}); {at}")  # fmt: skip


def _as_json(args: argparse.Namespace, settings: Any, runs: list[Any], results: dict[str, Any]
             ) -> dict[str, Any]:  # fmt: skip
    return {
        "runs": [r.name for r in runs],
        "minutes": sum(r.duration_s for r in runs) / 60,
        "folds": None if args.calibration else args.folds,
        "calibration": args.calibration,
        "gain_per_s": args.gain,
        "settings": vars(settings) | {"widths_s": list(settings.widths_s)},
        "detectors": {name: [vars(s) for s in per_joint] for name, per_joint in results.items()},
    }
