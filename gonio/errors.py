"""User-facing errors: each carries one clear line naming what is wrong."""

from __future__ import annotations


class GonioError(Exception):
    """An error the CLI reports as one line and a non-zero exit, without a traceback."""


class ConfigError(GonioError):
    """An instrument config is invalid; the message names the file and the field."""


class PlanError(GonioError):
    """A scan plan is invalid or cannot run on the instrument; names the field and the point."""


class RunError(GonioError):
    """A run directory is missing, damaged or cannot be resumed."""
