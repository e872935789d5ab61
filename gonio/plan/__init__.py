"""Scan plans: parse a plan file (parse), check it against an instrument (validate), order its
readings into the schedule the engine runs (schedule), estimate the time (estimate) and say it
in words (report). The names other code uses are re-exported here."""

from gonio.plan.estimate import estimate_seconds, positions, profile_seconds
from gonio.plan.parse import (
    AUTO_RANGE,
    CALIBRATES,
    KINDS,
    MOTION_ROLES,
    SIDES,
    Plan,
    SignaturePlan,
    load_plan,
    parse_plan,
)
from gonio.plan.report import describe_range, describe_ranges, format_duration, listing, summary
from gonio.plan.schedule import Schedule, build_schedule, serpentine
from gonio.plan.validate import stage_targets, sweeps_source

__all__ = [
    "AUTO_RANGE", "CALIBRATES", "KINDS", "MOTION_ROLES", "SIDES", "Plan", "Schedule",
    "SignaturePlan",
    "build_schedule", "describe_range", "describe_ranges", "estimate_seconds", "format_duration",
    "listing", "load_plan", "parse_plan", "positions", "profile_seconds", "serpentine",
    "stage_targets", "summary", "sweeps_source",
]
