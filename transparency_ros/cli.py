"""The ``transparency`` command: one entry point, one module per subcommand.

Each module in ``transparency_ros.commands`` exposes ``register(subparsers)``, which adds its
parser and sets ``func`` to a ``run(args) -> int``. Errors raised on purpose
(:class:`TransparencyError`) become one clear line on stderr and exit status 2; anything else
is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from transparency_ros import __version__
from transparency_ros.commands import compare, demo, discrepancy, evaluate, feelcage, model, rig
from transparency_ros.core.errors import TransparencyError

SUBCOMMANDS = (model, feelcage, rig, evaluate, discrepancy, compare, demo)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="transparency",
        description=(
            "Actuator transparency and proprioceptive contact detection "
            "(transparency_ros). Run 'transparency <command> --help' for details."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="<command>", required=True)
    for module in SUBCOMMANDS:
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except TransparencyError as err:
        print(f"transparency {args.command}: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `transparency model --json | head`
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
