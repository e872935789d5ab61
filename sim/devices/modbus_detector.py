"""Emulated Modbus photodiode amplifier + ADC, per its register map.

Each read of the `reading` registers asks the PowerSource for the true optical power now
and passes it through the PhotodiodeModel (gain ranges from the map, autorange, averaging,
saturation, noise); status, range in use and fault code describe that measurement, which
takes the map's `sample_s` per averaged sample on the bench's clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from sim.devices.faults import FaultSpec, InterlockInput
from sim.devices.modbus_server import EmulatedUnit
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import PhotodiodeModel, PowerSource
from sim.devices.register_map import ILLEGAL_VALUE, DeviceLayout, Field, LayoutError, Rejected

_FIELDS = ("reading", "status", "range_in_use", "fault_code", "gain_range", "autorange",
           "averaging", "wavelength", "command")
_COMMANDS = ("zero", "clear_fault")
_BITS = ("saturated", "fault")
_FAULTS = ("sensor",)


class ModbusDetectorEmulator(EmulatedUnit):
    """One photodiode amplifier unit reading a PowerSource through a PhotodiodeModel.

    detector: the instrument config's [sim.detector] table (its ranges_w, if given, must
    equal the map's gain ranges); light_wavelength_nm: the light's true wavelength (None =
    a perfectly corrected meter); place: the commanded stage positions now (deg), which key
    the noise (None: the range and the visit count only); serial, device_identification: as
    for EmulatedUnit; interlock: the amplifier's interlock input (while it is open a reading
    measures nothing: NaN with the map's `interlock` status bit set); clock: the bench's
    VirtualClock a reading takes its time on (the map's `sample_s` per averaged sample; None:
    no time).
    """

    def __init__(self, source: PowerSource, register_map_path: str | Path,
                 faults: FaultSpec | None = None, seed: int = 0,
                 detector: Mapping | None = None, light_wavelength_nm: float | None = None, *,
                 serial: str | None = None, device_identification: bool = True,
                 place: Callable[[], Sequence[float]] | None = None,
                 interlock: InterlockInput | None = None, clock: VirtualClock | None = None):
        layout = DeviceLayout.read(register_map_path)
        layout.need(_FIELDS, _COMMANDS, _BITS, _FAULTS)
        if not layout.ranges_w:
            raise LayoutError(f"{layout.source}: [gain_ranges] full_scale_w: missing")
        table = dict(detector or {})
        if "ranges_w" in table and tuple(table["ranges_w"]) != layout.ranges_w:
            raise LayoutError(f"[sim.detector] ranges_w: {table['ranges_w']!r} differ from the "
                              f"gain ranges of {layout.source}")
        super().__init__(layout, faults, serial=serial,
                         device_identification=device_identification)
        self.source = source
        self._place = place or tuple
        self.model = PhotodiodeModel({**table, "ranges_w": list(layout.ranges_w)}, seed=seed,
                                     light_wavelength_nm=light_wavelength_nm)
        for name, value in (("gain_range", len(layout.ranges_w) - 1), ("autorange", 1),
                            ("averaging", 1), ("wavelength", 632.8)):
            self.registers.set(name, value)
        self.fault: str | None = None
        self.saturated = False
        self.range_index = len(layout.ranges_w) - 1
        self.interlock, self.interlocked = interlock, False
        self.clock = clock

    def check(self, field: Field, value: float) -> None:
        super().check(field, value)
        if field.name == "gain_range" and value >= len(self.layout.ranges_w):
            raise Rejected(ILLEGAL_VALUE, f"gain range {value:g} past the range table")

    def refresh(self, fields: list[Field]) -> None:
        names = {f.name for f in fields}
        if self.interlock is not None:
            self.interlocked = self.interlock.poll()[1]
        if "reading" in names:
            self.registers.set("reading", math.nan if self.interlocked else self._measure())
            if self.clock is not None and not self.interlocked:
                self.clock.spend(self.registers.get("averaging") * self.layout.sample_s)
        bits = {"saturated": self.saturated, "fault": self.fault is not None,
                "interlock": self.interlocked}
        self.registers.set("status", sum(1 << self.layout.bits[b] for b, on in bits.items()
                                         if on and b in self.layout.bits))
        self.registers.set("range_in_use", self.range_index)
        self.registers.set("fault_code", self.layout.faults[self.fault][0] if self.fault else 0)

    def _measure(self) -> float:
        """One averaged measurement with the present settings; NaN and a fault if the source
        gives no valid power."""
        try:
            power = float(self.source.power_w())
        except Exception:  # noqa: BLE001 - any source failure is the sensor fault
            power = math.nan
        if not (math.isfinite(power) and power >= 0.0):
            self.fault, self.saturated = "sensor", False
            return math.nan
        fixed = None if self.registers.get("autorange") else self.layout.ranges_w[
            int(self.registers.get("gain_range"))]
        m = self.model.measure(power, range_w=fixed,
                               averaging=int(self.registers.get("averaging")),
                               wavelength_nm=self.registers.get("wavelength"),
                               place=self._place())
        self.fault, self.saturated = None, m.saturated
        self.range_index = self.layout.ranges_w.index(m.range_w)
        return m.reading_w

    def act(self, fields: list[Field]) -> None:
        if "command" not in {f.name for f in fields}:
            return
        command = self.take_command()
        if command == "zero":
            self.model.zero(self.registers.get("wavelength"))
        elif command == "clear_fault":
            self.fault = None
