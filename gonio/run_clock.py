"""The clock of a run: what a reading's `t_s` counts (seconds since the run first started) and
how long the engine's waits (settling, dwell, a suspension's recheck) take on it.

A real bench, or one with real devices in the loop, runs on the wall clock; a run whose
devices are all emulated runs on the emulated bench's virtual clock (gonio.simulate), so its
times, and the fits that use them, do not depend on the machine's load.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class RunClock:
    """now(): seconds since the run's first start; wait_s(seconds): the real seconds a wait of
    `seconds` on this clock takes (an instant virtual clock is advanced by it and says 0)."""

    now: Callable[[], float]
    wait_s: Callable[[float], float]


def wall_clock(t0_epoch: float, time_scale: float = 1.0) -> RunClock:
    """Wall seconds since t0_epoch (`time.time()` seconds); waits of device seconds last
    1/time_scale as long (the devices' time scale: 1 on a real bench, 0 s when instant)."""
    return RunClock(lambda: time.time() - t0_epoch,
                    lambda seconds: 0.0 if math.isinf(time_scale) else seconds / time_scale)
