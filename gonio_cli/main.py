"""The `gonio` command line: one sub-command per module in gonio_cli.commands.

Each command module defines `register(subparsers)`, which adds its parser and sets
`func(args) -> int`. Errors meant for the user are one line and a non-zero exit; so are a
Ctrl-C at any moment (even while the modules load), a file the system refuses (a full disk,
a missing folder) and a signal that ends a command; a closed pipe on stdout (`| head`) ends
the command quietly, as it does any Unix filter. A warning is one line too.
"""

from __future__ import annotations

import signal
import sys


def _interrupted_loading(signum: int, frame: object) -> None:
    print("gonio: interrupted", file=sys.stderr)
    raise SystemExit(128 + signum)


signal.signal(signal.SIGINT, _interrupted_loading)  # until main() runs: no import traceback

import argparse  # noqa: E402
import importlib  # noqa: E402
import os  # noqa: E402
import warnings  # noqa: E402

from drivers.base import DriverError  # noqa: E402
from gonio.errors import GonioError, Terminated, os_error_text  # noqa: E402
from gonio_cli import emulator_truth  # noqa: E402
from gonio_cli.incomplete import gate_runs  # noqa: E402

# Module names under gonio_cli.commands, in the order `gonio --help` lists them.
COMMANDS = [
    "scan",
    "plan",
    "queue",
    "emulate",
    "reduce",
    "plot",
    "fit",
    "export",
    "check",
    "devices",
    "watch",
    "calibrate",
    "lut",
    "sweep",
    "bench",
]


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (and exit 2), as every other error
    of the command line is; `--help` still prints the usage."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full parser, one sub-command per module in COMMANDS (each a OneLineParser)."""
    parser = OneLineParser(
        prog="gonio", description="A virtual gonioreflectometer with real instrument drivers."
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"gonio_cli.commands.{name}").register(sub)
    return parser


def _one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                      lineno: int, line: str | None = None) -> str:
    """A warning as the command line shows it: one line, as its errors are."""
    return f"gonio: warning: {message}\n"


def _quiet_stdout() -> None:
    """Point stdout at /dev/null, so that flushing it at exit raises nothing more."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    verb = "gonio"
    emulator_truth.install()
    warnings.formatwarning = _one_line_warning
    try:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        args = build_parser().parse_args(argv)
        verb = f"gonio {args.command}"
        if getattr(args, "check_args", None):  # the verb's argument checks that need no run
            args.check_args(args)
        gate_runs(verb, args)
        return int(args.func(args) or 0)
    except (GonioError, DriverError) as exc:
        print(f"{verb}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        _quiet_stdout()
        return 128 + signal.SIGPIPE
    except OSError as exc:
        print(f"{verb}: error: {os_error_text(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{verb}: interrupted", file=sys.stderr)
        return 130
    except Terminated as exc:
        print(f"{verb}: terminated by {exc}", file=sys.stderr)
        return 128 + exc.signum

