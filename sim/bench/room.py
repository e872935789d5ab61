"""The air around the emulated bench, which its environment sensors read: [sim.room]'s
temperature and relative humidity at the run's start, each drifting linearly in run time."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from sim.bench.config import read_table

HOUR_S = 3600.0


@dataclass(frozen=True)
class Room:
    """Temperature (deg C) and relative humidity (fraction) at run time 0, and their drifts
    per hour; `run_time` is the clock they drift on (seconds of the run)."""

    temperature_c: float
    humidity_rel: float
    temperature_drift_c_per_h: float
    humidity_drift_rel_per_h: float
    run_time: Callable[[], float]

    def now(self) -> tuple[float, float]:
        """(temperature in deg C, relative humidity in 0..1) at the run's time now."""
        hours = self.run_time() / HOUR_S
        humidity = self.humidity_rel + self.humidity_drift_rel_per_h * hours
        return (self.temperature_c + self.temperature_drift_c_per_h * hours,
                min(max(humidity, 0.0), 1.0))


def build_room(sim_config: Mapping, run_time: Callable[[], float]) -> Room:
    """The room of a [sim] table (its [sim.room], checked; SimConfigError naming a bad key)."""
    return Room(**read_table(sim_config, "room"), run_time=run_time)
