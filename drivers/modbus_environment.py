"""Temperature and humidity transmitter on Modbus (RTU or TCP), addressed through its register
map (examples/registermaps/xy-md02.toml: the XY-MD02's input registers).

Implements drivers.base.EnvironmentSensor: one read of the map's `temperature` (deg C) and
`humidity` (a fraction) registers per reading; a value outside what a room can hold (the
sensor's own error words) is a DeviceError naming it.
"""

from __future__ import annotations

import math
from pathlib import Path

from drivers.base import DeviceError, RoomReading
from drivers.byte_link import LineSettings
from drivers.modbus_transport import RTU_LINE, ModbusTimeouts
from drivers.modbus_unit import MappedUnit
from drivers.register_map import ROOM_REGISTERS, RegisterMap

TEMPERATURE_RANGE_C = (-100.0, 100.0)  # what gonio's [environment] takes


class ModbusEnvironment(MappedUnit):
    """A room temperature and humidity sensor on a Modbus unit."""

    def __init__(self, transport: str, port_or_host: str, unit: int,
                 register_map: str | Path | RegisterMap, *, name: str = "modbus-environment",
                 tcp_port: int = 502, line: LineSettings = RTU_LINE,
                 timeouts: ModbusTimeouts | None = None, read_retries: int = 2):
        super().__init__(transport, port_or_host, unit, register_map, name=name,
                         tcp_port=tcp_port, line=line, timeouts=timeouts,
                         read_retries=read_retries)
        try:
            self.map.require(ROOM_REGISTERS)
        except ValueError:
            self.close()
            raise

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
