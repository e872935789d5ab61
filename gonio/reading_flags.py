"""The flags the engine records on a reading (its `flags` field, comma-separated), and the
mask that picks them out of a run's readings."""

from __future__ import annotations

import numpy as np

RETRIED = "retried"  # a transient failure (timeout, garble, lost link, invalid reading) was retried
INVALID = "invalid"  # the detector had no reading on any try (PM100: SCPI not-a-number);
# power_w is then NaN: no light was measured, and reduction leaves the reading out


def flagged(readings: np.ndarray, flag: str) -> np.ndarray:
    """Boolean mask of the readings (a `Run.readings()` array) that carry `flag`."""
    return np.array([flag in str(f).split(",") for f in readings["flags"]], dtype=bool)
