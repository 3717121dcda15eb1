"""``transparency rig``: drop trials through the real nodes, one MCAP bag per trial."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from transparency_ros.core.errors import ConfigError

ACTUATORS = ("U10DD", "EC60", "T2822", "U10GB")
DEFAULT_HEIGHTS = "0.03,0.05,0.1,0.2,0.4,0.7,1.1"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "rig",
        help="record drop-test trials (Sec. 3.1) through the nodes as rosbag2 MCAP bags",
        description=(
            "Start actuator_driver (simulated actuator with the drop-test rig: shuttle on a "
            "vertical rail, compliant contact, 10 kHz DAQ) and contact_estimator as processes, "
            "drop the shuttle from each height and record each trial as a bag by the bag "
            "contract (README): /joint_states, /joint_commands, /contact, /estimated_effort, "
            "/load_cell, /shuttle/height, custom_data transparency.*. Bags go to "
            "OUT/<actuator>/h<height mm>_t<trial>/. Ctrl-C or SIGTERM keeps the trial in "
            "progress in a bag that opens, marked custom_data transparency.interrupted (eval "
            "skips it)."
        ),
    )
    p.add_argument("--actuator", nargs="+", default=list(ACTUATORS), choices=ACTUATORS)
    p.add_argument("--heights", default=DEFAULT_HEIGHTS, metavar="M,M,...",
                   help=f"drop heights [m] (default {DEFAULT_HEIGHTS})")  # fmt: skip
    p.add_argument("--trials", type=int, default=1, help="trials per height")
    p.add_argument("--seed", type=int, default=0, help="seed of the rig's sensor noise")
    p.add_argument("--out", default="rig_bags", help="directory for the bags")
    p.set_defaults(func=run)


def parse_heights(text: str) -> list[float]:
    try:
        heights = [float(x) for x in text.split(",") if x.strip()]
    except ValueError as err:
        raise ConfigError(f"--heights: {err}") from err
    if not heights or any(not 0.0 < h <= 2.0 for h in heights):
        raise ConfigError(f"--heights: need heights in (0, 2] m, got {text!r}")
    return heights


def run(args: argparse.Namespace) -> int:
    heights = parse_heights(args.heights)
    if args.trials < 1:
        raise ConfigError("--trials must be >= 1")
    from transparency_ros.ros.rig_run import (  # noqa: PLC0415 - needs rclpy
        TrialBag,
        existing_trials,
        run_rig,
    )

    out = Path(args.out)
    for actuator in args.actuator:  # every actuator's, before the first node starts
        taken = existing_trials(out, actuator, heights, args.trials)
        if taken:
            raise ConfigError(f"--out {out}: {taken}")
    total = len(args.actuator) * len(heights) * args.trials
    done = [0]

    def progress(text: str) -> None:
        done[0] += 1
        print(f"[{done[0]}/{total}] {text}", file=sys.stderr, flush=True)

    def written(bag: TrialBag) -> None:
        note = "  INTERRUPTED: the trial up to the signal" if bag.interrupted else ""
        print(f"{bag.path}  ({bag.messages} messages){note}", flush=True)

    count = 0
    for actuator in args.actuator:
        bags = run_rig(actuator, heights, out, trials_per_height=args.trials, seed=args.seed,
                       progress=progress, written=written)  # fmt: skip
        count += len(bags)
    print(f"{count} bags in {out}; evaluate with: transparency eval {out}", file=sys.stderr)
    return 0
