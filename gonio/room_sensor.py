"""The environment sensor's part of a run: its reading stored with every reading line
(temperature_c and humidity_rel, each with its type-B u from the sensor's stated accuracy),
and the run's environment made from those lines (their mean; u the sensor's and their spread).

The record and the exports take the run's environment from here when the instrument config
has an environment sensor, from the plan's [environment] otherwise (a plan may not state both:
gonio.plan's schedule refuses it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from drivers.base import EnvironmentSensor
from gonio.device_kinds import KINDS, device_spec
from gonio.environment import Environment

#: what a reading line says of the room: value and standard uncertainty of each quantity
ROOM_FIELDS = ("temperature_c", "u_temperature_c", "humidity_rel", "u_humidity_rel")


@dataclass(frozen=True)
class RoomReadout:
    """An environment sensor and the 1-sigma u of its temperature (deg C) and humidity
    (fraction) readings, from its kind's specification (the accuracy a / sqrt(3))."""

    sensor: EnvironmentSensor
    u_temperature_c: float
    u_humidity_rel: float

    def read(self) -> dict[str, float]:
        """The room now, as a reading line stores it (ROOM_FIELDS)."""
        room = self.sensor.read_room()
        return {"temperature_c": room.temperature_c, "u_temperature_c": self.u_temperature_c,
                "humidity_rel": room.humidity_rel, "u_humidity_rel": self.u_humidity_rel}


def room_readout(sensor: EnvironmentSensor | None, config: Mapping[str, Any],
                 device: str | None) -> RoomReadout | None:
    """The readout of the config's (raw table's) environment sensor `device`, opened as
    `sensor`; None without one. Its kind's check has made sure the accuracies are stated."""
    if sensor is None or device is None:
        return None
    spec = device_spec(config, device)
    return RoomReadout(sensor, spec.temperature_c.sigma, spec.humidity_rel.sigma)


def sensor_of_config(config: Mapping[str, Any]) -> str | None:
    """The environment sensor of a stored (raw) config, by name; None without one."""
    devices = config.get("devices", {})
    for name, table in devices.items() if isinstance(devices, Mapping) else ():
        kind = KINDS.get(table.get("protocol")) if isinstance(table, Mapping) else None
        if kind is not None and kind.role == "environment":
            return name
    return None


def environment_of_lines(rows: Sequence[Mapping[str, Any]], sensor: str) -> Environment | None:
    """The run's environment from its reading lines' room fields: each quantity's mean, its u
    the root sum of squares of the sensor's u (one sensor, the same error in every reading,
    so it does not average down) and the readings' standard deviation (the room's change over
    the run); None when no line has a temperature."""
    temperature = _summary(rows, "temperature_c")
    if temperature is None:
        return None
    humidity = _summary(rows, "humidity_rel")
    count = sum(1 for row in rows if _number(row.get("temperature_c")))
    return Environment(
        temperature_c=temperature[0], u_temperature_c=temperature[1],
        humidity_rel=None if humidity is None else humidity[0],
        u_humidity_rel=None if humidity is None else humidity[1],
        notes=f"environment sensor {sensor}: mean of {count} readings; u combines the "
              f"sensor's accuracy and the readings' standard deviation")


def _summary(rows: Sequence[Mapping[str, Any]], key: str) -> tuple[float, float] | None:
    """(mean, u) of the lines' `key` values, u from their `u_<key>` and spread."""
    values = [float(row[key]) for row in rows if _number(row.get(key))]
    if not values:
        return None
    sensor_u = [float(row[f"u_{key}"]) for row in rows if _number(row.get(f"u_{key}"))]
    mean = math.fsum(values) / len(values)
    spread = (math.fsum((v - mean) ** 2 for v in values) / (len(values) - 1)
              if len(values) > 1 else 0.0)
    u_sensor = max(sensor_u, default=0.0)
    return mean, math.sqrt(u_sensor ** 2 + spread)


def _number(value: Any) -> bool:
    """A finite number (a line's null, NaN or missing field is none)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
