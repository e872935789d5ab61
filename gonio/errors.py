"""User-facing errors: each carries one clear line naming what is wrong."""

from __future__ import annotations

import signal


class GonioError(Exception):
    """An error the CLI reports as one line and a non-zero exit, without a traceback."""


class ConfigError(GonioError):
    """An instrument config is invalid; the message names the file and the field."""


class PlanError(GonioError):
    """A scan plan is invalid or cannot run on the instrument; names the field and the point."""


class RunError(GonioError):
    """A run directory is missing, damaged or cannot be resumed."""


class QueueError(GonioError):
    """A queue file is invalid (the message names the entry and the field), or the queue is
    being run by another process."""


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: a run aborts at once, a command ends with 128 + signum (a
    BaseException, so that no retry or `except Exception` swallows it)."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def os_error_text(exc: OSError) -> str:
    """An OSError as one line: the file it is about (when it names one), then what it is."""
    what = exc.strerror or str(exc) or type(exc).__name__
    return f"{exc.filename}: {what}" if exc.filename else what
