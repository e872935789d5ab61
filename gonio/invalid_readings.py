"""How many readings without a value (flagged `invalid`, gonio.reading_flags) a run may hold:
the plan's `max_invalid_share` of its planned readings (default DEFAULT_MAX_INVALID_SHARE).
The engine counts them as they are stored and stops the run, failed, as soon as the share can
no longer be met, rather than measuring the rest blind; a run that ends without one valid
reading fails too, whatever the share, with a reason naming the detector."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from gonio.reading_flags import INVALID

#: A lab's tolerance: a reading in ten without a value means a fault to mend (a missing or
#: failing sensor head, a loose cable), not noise; one now and then is retried and left out.
DEFAULT_MAX_INVALID_SHARE = 0.1


def is_invalid(record: dict[str, Any]) -> bool:
    """Whether a stored line carries the `invalid` flag."""
    return INVALID in str(record.get("flags") or "").split(",")


class InvalidReadings:
    """The count of a run's invalid readings against its allowance: `detector` names the
    detector for the reason, `planned` the run's planned readings, `share` the plan's
    max_invalid_share; `stored` the lines stored before this session."""

    def __init__(self, detector: str, planned: int, share: float,
                 stored: Iterable[dict[str, Any]] = ()):
        self.detector, self.planned, self.share = detector, planned, share
        self.allowed = math.floor(share * planned + 1e-9)
        self.invalid = self.valid = 0
        for record in stored:
            self.count(record)

    def count(self, record: dict[str, Any]) -> None:
        """Count one stored reading."""
        if is_invalid(record):
            self.invalid += 1
        else:
            self.valid += 1

    def _counts(self) -> str:
        return f"{self.invalid} of {self.invalid + self.valid} readings stored are invalid"

    def too_many(self) -> str | None:
        """Why the run must stop (more invalid readings than the share allows), else None."""
        if self.invalid <= self.allowed:
            return None
        none = " gave no valid reading:" if self.valid == 0 else ":"
        return (f"detector {self.detector!r}{none} {self._counts()}, more than "
                f"max_invalid_share {self.share:g} of the {self.planned} planned readings "
                f"allows ({self.allowed}); stopped rather than measure the rest without a "
                f"value (check the detector: its sensor head, its cable)")

    def none_valid(self) -> str | None:
        """Why a run that measured everything failed all the same (no valid reading), else
        None."""
        if self.valid or not self.invalid:
            return None
        return (f"detector {self.detector!r} gave no valid reading: {self._counts()} "
                f"(check the detector: its sensor head, its cable)")
