"""The PM100 family consoles and Thorlabs C-series sensor heads the PM100 emulator can be.

A console answers *IDN? as `Thorlabs,<model>,<serial>,<firmware>`. The manuals write the
format `THORLABS,MMM,SSS,X.X.X`; the units answer with the name in mixed case, as logs of real
units in public code show: `Thorlabs,PM100USB,P2004081,1.4.0`,
`Thorlabs,PM100A,P1003352,2.4.0`, `Thorlabs,PM100D,P0027168,2.7.0`
(tests/devices_serial/test_pm100_manual_examples.py checks the emulator against them). It
has the front-panel functions its manual gives it (display brightness and contrast, clock,
beeper). A head answers SYST:SENS:IDN? as `name,serial,calibration,type,subtype,flags` (type
1 photodiode, 2 thermopile; subtype 2 standard, 3 with a filter slide, 0x12 with a
temperature sensor; flags 1 power sensor, 16 response settable, 32 wavelength settable, 64
tau settable, 256 temperature sensor, as Thorlabs' TLPM.h defines them) and bounds the
correction wavelength, as Thorlabs gives each head's wavelength range.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class Console:
    """A PM100-family console: its *IDN? fields and front-panel functions."""

    model: str
    serial: str
    firmware: str
    display: tuple[str, ...] = ()  # the DISPlay settings it has: BRIGhtness, CONTrast
    clock: bool = False  # SYSTem:DATE and :TIME
    beeper: bool = False  # SYSTem:BEEPer

    @property
    def idn(self) -> str:
        """The *IDN? answer."""
        return f"Thorlabs,{self.model},{self.serial},{self.firmware}"


CONSOLES = {console.model: console for console in (
    Console("PM100D", "P0000000", "2.4.0", display=("BRIGhtness", "CONTrast"), clock=True,
            beeper=True),
    Console("PM100A", "P1000000", "1.3.0", display=("BRIGhtness",), beeper=True),
    Console("PM100USB", "P2000000", "1.7.0"),
    Console("PM400", "P5000000", "1.8.2", display=("BRIGhtness",)),
)}


@dataclass(frozen=True)
class SensorHead:
    """A C-series sensor head: SYST:SENS:IDN? fields, its wavelength range (nm) and its
    aperture (mm, the default beam diameter)."""

    name: str
    kind: Literal["photodiode", "thermal"]
    wavelength_min_nm: float
    wavelength_max_nm: float
    subtype: int = 2
    aperture_mm: float = 9.5
    serial: str = "EMU00001"
    calibration: str = "01-Jan-2026"

    @property
    def type(self) -> int:
        """SYST:SENS:IDN? type: 1 photodiode, 2 thermopile."""
        return 1 if self.kind == "photodiode" else 2

    @property
    def flags(self) -> int:
        """Power sensor, response and wavelength settable; a thermopile's tau too; a head
        with a temperature sensor (subtype 0x12) says so."""
        flags = 1 + 16 + 32 + (64 if self.kind == "thermal" else 0)
        return flags + (256 if self.subtype == 0x12 else 0)

    @property
    def range_text(self) -> str:
        """Its wavelength range as people write it: 400-1100 nm."""
        return f"{self.wavelength_min_nm:g}-{self.wavelength_max_nm:g} nm"


HEADS = {head.name: head for head in (
    SensorHead("S120C", "photodiode", 400.0, 1100.0),  # Si
    SensorHead("S121C", "photodiode", 400.0, 1100.0),  # Si, higher power
    SensorHead("S130C", "photodiode", 400.0, 1100.0, subtype=3),  # slim Si, filter slide
    SensorHead("S122C", "photodiode", 700.0, 1800.0),  # Ge
    SensorHead("S302C", "thermal", 190.0, 25000.0, subtype=0x12),  # thermal, 0.19-25 um
)}
DEFAULT_HEAD = "S121C"


def _named(table: dict, name: str, what: str):
    if name not in table:
        raise ValueError(f"pm100: no {what} {name!r} (known: {', '.join(table)})")
    return table[name]


def console(model: str) -> Console:
    """The console called `model` (PM100D, PM100A, PM100USB, PM400), or ValueError."""
    return _named(CONSOLES, model, "console model")


def head(name: str) -> SensorHead:
    """The sensor head called `name` (S120C, S121C, S130C, S122C, S302C), or ValueError."""
    return _named(HEADS, name, "sensor head")
