"""The `gonio` command line: one sub-command per module in gonio.commands.

Each command module defines `register(subparsers)`, which adds its parser and sets
`func(args) -> int`. Errors meant for the user are one line and a non-zero exit.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from drivers.base import DriverError
from gonio.errors import GonioError

# Module names under gonio.commands, in the order `gonio --help` lists them.
COMMANDS = [
    "scan",
    "plan",
    "emulate",
    "reduce",
    "plot",
    "fit",
    "export",
    "check",
    "calibrate",
    "lut",
    "sweep",
    "bench",
]


def build_parser() -> argparse.ArgumentParser:
    """The full parser, one sub-command per module in COMMANDS."""
    parser = argparse.ArgumentParser(
        prog="gonio", description="A virtual gonioreflectometer with real instrument drivers."
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"gonio.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (GonioError, DriverError) as exc:
        print(f"gonio {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"gonio {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
