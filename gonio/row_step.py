"""One schedule row's step, shared by the scan engine and the Bluesky plan as ophyd-async
shares a movable's logic: which axes move where, how long to settle and dwell after the moves,
and the arrival check every move ends with."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from drivers.base import DriverError
from gonio.instrument import Instrument


class PositionMismatch(DriverError):
    """An axis reports a position other than the target it was sent to (twice running)."""

    def __init__(self, role: str, position_deg: float, target_deg: float, tolerance_deg: float):
        self.position_deg = position_deg
        super().__init__(f"{role} axis at {position_deg:.6g} deg, not at its target "
                         f"{target_deg:.6g} deg (tolerance {tolerance_deg:g})")


@dataclass(frozen=True)
class RowStep:
    """What a schedule row asks of the instrument: the detector range (W; AUTO_RANGE
    autoranges), every axis's target (deg), the axes that must move (their target is not the
    one last commanded), and the device seconds to wait once they arrived (the slowest moved
    axis's settling plus the plan's dwell)."""

    range_w: float
    targets: dict[str, float]
    moved: list[str]
    hold_s: float


def row_step(instrument: Instrument, row: np.void, commanded: Mapping[str, float | None],
             dwell_s: float) -> RowStep:
    """The step of `row` when the axes were last commanded to `commanded` (None: unknown)."""
    targets = {role: float(row[f"{role}_deg"]) for role in instrument.axes}
    moved = [role for role, target in targets.items() if commanded[role] != target]
    settle_s = max((instrument.config.axes[role].settle_s for role in moved), default=0.0)
    return RowStep(float(row["range_w"]), targets, moved, settle_s + dwell_s)


@dataclass(frozen=True)
class Arrival:
    """The check that ends a move of the role's axis to target: a reported position within
    tolerance_deg has arrived; one off target is read once more (a garbled reply can be a
    plausible number) and must be within it then."""

    role: str
    target_deg: float
    tolerance_deg: float

    def holds(self, position_deg: float) -> bool:
        """The position is the target, within the tolerance."""
        return abs(position_deg - self.target_deg) <= self.tolerance_deg

    def confirm(self, again_deg: float) -> float:
        """The position read again after an off-target report: it, if it holds, else
        PositionMismatch."""
        if self.holds(again_deg):
            return again_deg
        raise PositionMismatch(self.role, again_deg, self.target_deg, self.tolerance_deg)


def arrival(instrument: Instrument, role: str, target_deg: float) -> Arrival:
    """The arrival check of a move of the role's axis to target_deg (the config's tolerance)."""
    return Arrival(role, target_deg, instrument.config.axes[role].tolerance_deg)
