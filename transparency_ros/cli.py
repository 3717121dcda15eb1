"""The ``transparency`` command: one entry point, one module per subcommand.

Each module in ``transparency_ros.commands`` exposes ``register(subparsers)``, which adds its
parser and sets ``func`` to a ``run(args) -> int``. Errors raised on purpose
(:class:`TransparencyError`) become one clear line on stderr and exit status 2; anything else
is a bug and keeps its traceback. Ctrl-C and SIGTERM unwind the command (its bags are closed,
its node processes stopped), print one line, and exit with 128 + the signal's number.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence

from transparency_ros import __version__
from transparency_ros.commands import (
    assay,
    compare,
    demo,
    detect,
    discrepancy,
    evaluate,
    feelcage,
    model,
    rig,
    salvage,
)
from transparency_ros.core.errors import TransparencyError
from transparency_ros.core.interrupts import (
    interrupt_on_sigint,
    interruption_name,
    terminate_like_interrupt,
)

SUBCOMMANDS = (model, feelcage, rig, evaluate, salvage, discrepancy, compare, detect, assay, demo)


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
    previous = signal.getsignal(signal.SIGTERM)
    terminate_like_interrupt()  # SIGTERM unwinds like Ctrl-C: bags closed, nodes stopped
    previous_int = interrupt_on_sigint()  # and SIGINT too when started with it ignored
    try:
        return int(args.func(args))
    except TransparencyError as err:
        print(f"transparency {args.command}: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `transparency model --json | head`
        return 0
    except KeyboardInterrupt as err:
        name = interruption_name(err)
        print(f"transparency {args.command}: stopped by {name}", file=sys.stderr)
        return 128 + signal.Signals[name].value
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
