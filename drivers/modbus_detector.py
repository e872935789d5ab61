"""Photodiode amplifier + ADC on Modbus (RTU or TCP), addressed through its register map.

Implements drivers.base.Detector (and Interlock: a reading whose status has the map's optional
`interlock` bit set raises Interlocked): wavelength correction, averaging, a fixed gain range
or autorange, one reading per call, and the dark zero.
"""

from __future__ import annotations

import math

from drivers.base import DeviceError, Reading
from drivers.modbus_unit import MappedUnit

DETECTOR_REGISTERS = ("reading", "status", "range_in_use", "fault_code", "gain_range",
                      "autorange", "averaging", "wavelength", "command")
DETECTOR_COMMANDS = ("zero", "clear_fault")
DETECTOR_BITS = ("saturated", "fault")


class ModbusDetector(MappedUnit):
    """An optical power detector on a Modbus photodiode amplifier."""

    kind_name = "modbus-detector"
    needs = (DETECTOR_REGISTERS, DETECTOR_COMMANDS, DETECTOR_BITS)

    def check_map(self) -> None:
        """The registers, commands and bits it needs, and the gain ranges' full scales."""
        super().check_map()
        if not self.map.gain_ranges_w:
            raise ValueError(f"{self.map.source}: [gain_ranges] full_scale_w is missing")

    @property
    def ranges_w(self) -> tuple[float, ...]:
        """Full scale of each gain range, W, by index (from the map)."""
        return self.map.gain_ranges_w

    def full_scales_w(self) -> tuple[float, ...]:
        """Full scale of each gain range, W, increasing (drivers.base.Detector)."""
        return self.ranges_w

    def range_index(self, range_w: float) -> int:
        """Index of the smallest gain range whose full scale holds range_w (ValueError past the
        largest)."""
        for i, full_scale in enumerate(self.ranges_w):
            if range_w <= full_scale * (1 + 1e-9):
                return i
        raise ValueError(f"{self.name}: range {range_w!r} W above the largest range "
                         f"{self.ranges_w[-1]:g} W")

    def configure(self, wavelength_nm: float, averaging: int, range_w: float | None) -> None:
        """Set correction wavelength, samples averaged per reading, fixed range (None = auto);
        every value is checked against the map before anything is written."""
        if isinstance(averaging, bool) or int(averaging) != averaging:
            raise ValueError(f"{self.name}: averaging must be an integer, got {averaging!r}")
        if range_w is not None and not (math.isfinite(range_w) and range_w > 0):
            raise ValueError(f"{self.name}: range must be a power > 0 W or None, got {range_w!r}")
        values = {"wavelength": wavelength_nm, "averaging": int(averaging),
                  "autorange": 1 if range_w is None else 0}
        if range_w is not None:
            values["gain_range"] = self.range_index(range_w)
        self.write_values(values)

    def settings(self) -> dict[str, float]:
        """The amplifier's settings: wavelength (nm), averaging, autorange, gain_range."""
        return self.read_values("wavelength", "averaging", "autorange", "gain_range")

    def read(self) -> Reading:
        """Take one averaged reading; DeviceError if the amplifier reports a fault."""
        v = self.read_values("reading", "status", "range_in_use", "fault_code")
        bits = self.bits(v["status"])
        self.check_interlock(bits)
        if bits["fault"]:
            code = int(v["fault_code"])
            raise DeviceError(self.name, code, self.map.fault_text(code))
        index = int(v["range_in_use"])
        if not 0 <= index < len(self.ranges_w):
            raise DeviceError(self.name, "range", f"range index {index} not in the map")
        return Reading(v["reading"], self.ranges_w[index], bits["saturated"])

    def zero(self) -> None:
        """Dark zero: the amplifier takes the present (dark) signal as its offset."""
        self.command("zero")

    def clear_fault(self) -> None:
        """Clear the amplifier's fault code and bit."""
        self.command("clear_fault")
