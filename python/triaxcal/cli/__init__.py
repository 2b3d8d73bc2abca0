"""The ``triaxcal`` command line. Each subcommand lives in its own module of this package and
exposes ``register(subparsers)``; ``main`` dispatches to the function it sets as ``func``."""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from .. import __version__
from .._checks.spelling import command_line
from ..errors import CalibrationError, RefusedError
from ..io.files import os_error_message
from ._help import PlainHelpFormatter, missing_required

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ("demo", "capture", "fit", "batch", "export", "report", "send", "sphere_center",
            "tilt_rig", "gyro_gains", "temperature", "ferraris", "imu", "turntable", "noise",
            "diff", "board")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="triaxcal",
        description="Calibrate three-axis accelerometers, gyroscopes and magnetometers.",
    )
    parser.add_argument("--version", action="version", version=f"triaxcal {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:  # a subcommand not written yet
            if exc.name == f"{__name__}.{name}":
                continue
            raise
        mod.register(sub)
    for command in sub.choices.values():  # plain text, defaults shown, for every command
        command.formatter_class = PlainHelpFormatter
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    missing = missing_required(args)
    if missing:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        sub.choices[args.command].error(
            f"the following arguments are required: {', '.join(missing)}")
    try:
        with command_line():  # messages name the options as flags
            return int(args.func(args) or 0)
    except RefusedError as exc:  # refused (the validity gate, data not at rest): nothing written
        print(f"triaxcal {args.command}: {exc.verb}: {exc}", file=sys.stderr)
        return 2
    except CalibrationError as exc:
        print(f"triaxcal {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a file problem no command turned into a message of its own
        where = exc.filename if exc.filename is not None else "a file"
        print(f"triaxcal {args.command}: error: {os_error_message(exc, where)}",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"triaxcal {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
