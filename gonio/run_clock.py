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
    `seconds` on this clock takes (an instant virtual clock is advanced by it and says 0);
    run_s_per_device_s: seconds of this clock a second of the devices' time lasts."""

    now: Callable[[], float]
    wait_s: Callable[[float], float]
    run_s_per_device_s: float = 1.0

    def device_wait_s(self, device_s: float) -> float:
        """Real seconds a wait of device_s seconds of the devices' time (settling, dwell)
        takes."""
        return self.wait_s(device_s * self.run_s_per_device_s)


def wall_clock(t0_epoch: float, time_scale: float = 1.0) -> RunClock:
    """Wall seconds since t0_epoch (`time.time()` seconds), on which a second of devices that
    run time_scale times faster (1 on a real bench; inf: instant) lasts 1/time_scale."""
    return RunClock(lambda: time.time() - t0_epoch, lambda seconds: seconds,
                    0.0 if math.isinf(time_scale) else 1.0 / time_scale)
