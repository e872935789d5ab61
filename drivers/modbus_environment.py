"""Temperature and humidity transmitter on Modbus (RTU or TCP), addressed through its register
map (examples/registermaps/xy-md02.toml: the XY-MD02's input registers).

Implements drivers.base.EnvironmentSensor: one read of the map's `temperature` (deg C) and
`humidity` (a fraction) registers per reading; a value outside what a room can hold (the
sensor's own error words) is a DeviceError naming it.
"""

from __future__ import annotations

import math

from drivers.base import DeviceError, RoomReading
from drivers.modbus_unit import MappedUnit
from drivers.register_map import ROOM_REGISTERS

TEMPERATURE_RANGE_C = (-100.0, 100.0)  # what gonio's [environment] takes


class ModbusEnvironment(MappedUnit):
    """A room temperature and humidity sensor on a Modbus unit."""

    kind_name = "modbus-environment"
    needs = (ROOM_REGISTERS, (), ())

    def read_room(self) -> RoomReading:
        """Temperature (deg C) and relative humidity (fraction) now, in one read."""
        v = self.read_values(*ROOM_REGISTERS)
        low, high = TEMPERATURE_RANGE_C
        if not (math.isfinite(v["temperature"]) and low <= v["temperature"] <= high):
            raise DeviceError(self.name, "temperature",
                              f"{v['temperature']:g} degC is no room temperature")
        if not (math.isfinite(v["humidity"]) and 0.0 <= v["humidity"] <= 1.0):
            raise DeviceError(self.name, "humidity",
                              f"relative humidity {v['humidity']:g} is not in 0..1")
        return RoomReading(v["temperature"], v["humidity"])
