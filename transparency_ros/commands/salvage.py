"""``transparency salvage``: copy the readable part of a damaged bag into a new bag."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.salvage import salvage
from transparency_ros.core import strict_json


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "salvage",
        help="recover the readable messages of a truncated or damaged bag (MCAP or sqlite3)",
        description=(
            "Read a bag that does not open (a recording cut short, a damaged file) record by "
            "record and write what is readable into a new MCAP bag, with the original "
            "custom_data and custom_data transparency.salvaged saying what was lost. Prints, "
            "per topic, the messages salvaged against the count metadata.yaml recorded. Exit "
            "status 0 when something was salvaged, 2 when nothing could be."
        ),
    )
    p.add_argument("bag", metavar="BAG", help="bag directory, or one .mcap / .db3 file")
    p.add_argument("--out", metavar="DIR", help="the new bag (default BAG.salvaged)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    report = salvage(args.bag, args.out, lambda text: print(text, file=sys.stderr, flush=True))
    if args.json:
        strict_json.dump({"source": str(report.source), "out": report.out and str(report.out),
                          "kept": dict(report.kept), "recorded": report.recorded,
                          "damage": report.damage}, sys.stdout)  # fmt: skip
    else:
        for line in report.damage:
            print(f"damage: {line}")
        topics = sorted(set(report.kept) | set(report.recorded))
        if topics:
            print(f"{'topic':<32} {'salvaged':>9} {'recorded':>9}")
        for topic in topics:
            recorded = report.recorded.get(topic)
            print(f"{topic:<32} {report.kept.get(topic, 0):>9} "
                  f"{'-' if recorded is None else recorded:>9}")  # fmt: skip
    if report.out is None:
        raise BagReadError(f"{report.source}: nothing could be salvaged")
    print(f"{report.total} messages salvaged into {report.out}", file=sys.stderr)
    return 0
