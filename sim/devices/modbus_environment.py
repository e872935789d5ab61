"""Emulated Modbus temperature and humidity transmitter (the XY-MD02), per its register map.

Each read of the `temperature` or `humidity` input registers reports the room now (the bench's
[sim.room] on the run's clock) plus the map's optional `temperature_correction` and
`humidity_correction` holding registers, as the XY-MD02 manual describes them; the registers'
0.1 deg C and 0.1 %RH steps are the quantisation. The device answers no function 43: it
reports no identity. Address and baud-code writes are stored (the device takes them at its
next power-up, which the emulator never has).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from sim.devices.faults import FaultSpec
from sim.devices.modbus_server import EmulatedUnit
from sim.devices.register_map import DeviceLayout, Field

_FIELDS = ("temperature", "humidity")
_CORRECTIONS = {"temperature": "temperature_correction", "humidity": "humidity_correction"}


class ModbusEnvironmentEmulator(EmulatedUnit):
    """One temperature and humidity unit reading `room()`: (deg C, relative humidity 0..1)."""

    def __init__(self, room: Callable[[], tuple[float, float]], register_map_path: str | Path,
                 faults: FaultSpec | None = None, *, serial: str | None = None):
        layout = DeviceLayout.read(register_map_path)
        layout.need(_FIELDS, (), (), ())
        super().__init__(layout, faults, serial=serial, device_identification=False)
        self.room = room
        if "device_address" in layout.fields:
            self.registers.set("device_address", 1)

    def refresh(self, fields: list[Field]) -> None:
        names = {f.name for f in fields}
        if not names & set(_FIELDS):
            return
        values = dict(zip(_FIELDS, self.room(), strict=True))
        for name in _FIELDS:
            correction = _CORRECTIONS[name]
            offset = self.registers.get(correction) if correction in self.layout.fields else 0.0
            value = values[name] + offset
            self.registers.set(name, min(max(value, 0.0), 1.0) if name == "humidity" else value)
