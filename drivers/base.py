"""The small interface every driver gives the scan engine, and the errors it raises.

An engine only ever sees `Axis`, `Detector` and `WavelengthSelector`; which protocol and
transport sit behind them is the config's business.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

DATA_OUT_OF_RANGE = -222  # the SCPI error a setting outside its limits raises


class DriverError(Exception):
    """Base of every driver failure; the message names the device."""


class DeviceError(DriverError):
    """The device reported an error (its own code and text are in the message)."""

    def __init__(self, device: str, code: int | str, text: str):
        self.device, self.code, self.text = device, code, text
        super().__init__(f"{device}: device error {code}: {text}")


class DeviceTimeout(DriverError):
    """No complete reply within the named timeout."""

    def __init__(self, device: str, what: str, timeout_s: float):
        self.device, self.what, self.timeout_s = device, what, timeout_s
        super().__init__(f"{device}: timeout after {timeout_s:g} s waiting for {what}")


class Interlocked(DeviceError):
    """The device reports an interlock or emergency stop: it has stopped, and refuses to run
    until the condition clears (Interlock.release_interlock says when)."""


class ProtocolError(DriverError):
    """A reply arrived but was garbled or not what the protocol allows."""


class InvalidReading(DriverError):
    """The detector answered that it has no reading (SCPI's not-a-number, 9.91E+37): no
    power, and not over range either; worth asking again."""

    def __init__(self, device: str, range_w: float, what: str):
        self.device, self.range_w = device, range_w
        super().__init__(f"{device}: invalid reading ({what}) on the {range_w:g} W range")


@runtime_checkable
class Axis(Protocol):
    """One rotation axis, positions in degrees."""

    name: str

    def configure(self, speed_deg_s: float, accel_deg_s2: float,
                  limits_deg: tuple[float, float]) -> None:
        """Set the speed and acceleration of the next moves and the software travel limits."""

    def move_to(self, position_deg: float) -> None:
        """Start an absolute move and return at once (never blocks for the motion)."""

    def position(self) -> float:
        """Actual position now, degrees."""

    def is_moving(self) -> bool:
        """True while a move or home is in progress."""

    def wait(self, timeout_s: float) -> float:
        """Block until motion is done (DeviceTimeout past timeout_s); return the final position."""

    def stop(self) -> None:
        """Decelerate to a stop (safe to call at any time)."""

    def home(self) -> None:
        """Start a homing move; wait() waits for it."""

    def identity(self) -> dict[str, str]:
        """The device's identity as it reports it (model, serial, firmware...; {} if it
        reports none). Axes of one controller report the controller's identity."""


@runtime_checkable
class WavelengthSelector(Protocol):
    """A device that selects the light's wavelength, in nm: a filter wheel (the filter centred
    on it) or a monochromator (its grating turned to it)."""

    name: str

    def move_to_nm(self, wavelength_nm: float) -> None:
        """Start selecting wavelength_nm (ValueError for one the device is not set up to
        select, as far as the driver knows; a device's refusal may come with wait())."""

    def wait(self, timeout_s: float) -> float:
        """Block until the selection is done (DeviceTimeout past timeout_s); return the
        wavelength the device reports, nm."""

    def wavelength_nm(self) -> float:
        """The wavelength selected now, nm."""

    def identity(self) -> dict[str, str]:
        """The device's identity as it reports it ({} if it reports none)."""

    def close(self) -> None:
        """Release the connection."""


@runtime_checkable
class Interlock(Protocol):
    """A device that reports an interlock input (an emergency stop, a door switch)."""

    name: str

    def release_interlock(self) -> str | None:
        """Get ready to run again if the interlock has cleared (None), else say what still
        holds it."""


@runtime_checkable
class LineCounts(Protocol):
    """A device on a line that counts what the line has seen, for the run's record."""

    def line_counts(self) -> dict[str, int]:
        """Counts by name since the device was opened (a line transport's `resyncs`, sync
        queries answered, and `unsolicited`, unprompted lines set aside)."""


@runtime_checkable
class HeadRange(Protocol):
    """A detector whose sensor head tells the wavelengths it takes and its name, asked without
    setting anything (a PM100's head: SENS:CORR:WAV? MIN / MAX, SYST:SENS:IDN?)."""

    name: str

    def wavelength_limits_nm(self) -> tuple[float, float]:
        """The lowest and highest wavelength the head takes, nm."""

    def head_name(self) -> str:
        """The connected head's name as it reports it."""


class WavelengthOutsideHead(DeviceError):
    """The connected sensor head cannot take the correction wavelength asked for (the meter
    refused it as out of range): names the wavelength, the head and the head's range."""

    def __init__(self, device: str, wavelength_nm: float, head: str,
                 limits_nm: tuple[float, float]):
        super().__init__(device, DATA_OUT_OF_RANGE, "Data out of range")
        self.wavelength_nm, self.head, self.limits_nm = wavelength_nm, head, limits_nm

    @classmethod
    def asked(cls, meter: HeadRange, wavelength_nm: float) -> WavelengthOutsideHead | None:
        """Whether the meter's head can take wavelength_nm, asked without setting it (its
        range and its name, HeadRange): the error a setting would meet, or None when the
        range holds it."""
        low, high = meter.wavelength_limits_nm()
        if low <= wavelength_nm <= high:
            return None
        return cls(meter.name, wavelength_nm, meter.head_name(), (low, high))

    @property
    def reason(self) -> str:
        """The wavelength, the head and its range, each number in as many digits as tell it
        apart (1100.0004 nm is outside 400-1100 nm, never "1100 nm is outside")."""
        low, high = (self.nm(limit) for limit in self.limits_nm)
        return (f"wavelength {self.nm(self.wavelength_nm)} nm is outside the sensor head "
                f"{self.head}'s range {low}-{high} nm")

    @staticmethod
    def nm(value: float) -> str:
        """A wavelength in the fewest digits that give it back exactly (1550, 1100.0004)."""
        return repr(float(value)).removesuffix(".0")

    def __str__(self) -> str:
        return f"{self.device}: {self.reason}"


@dataclass(frozen=True)
class Reading:
    """One detector reading: optical power in W and what the device said about it."""

    power_w: float
    range_w: float
    saturated: bool = False


@dataclass(frozen=True)
class RoomReading:
    """One environment-sensor reading: air temperature in deg C, relative humidity as a
    fraction (0 to 1)."""

    temperature_c: float
    humidity_rel: float


@runtime_checkable
class EnvironmentSensor(Protocol):
    """A room temperature and humidity sensor, read beside the detector."""

    name: str

    def read_room(self) -> RoomReading:
        """The temperature and humidity now."""

    def identity(self) -> dict[str, str]:
        """The device's identity as it reports it ({} if it reports none)."""

    def close(self) -> None:
        """Release the connection."""


@runtime_checkable
class Detector(Protocol):
    """An optical power detector."""

    name: str

    def configure(self, wavelength_nm: float, averaging: int, range_w: float | None) -> None:
        """Set the correction wavelength, samples per reading, and a fixed range (None = auto)."""

    def full_scales_w(self) -> tuple[float, ...]:
        """Full scale of every range the detector offers, W, increasing."""

    def read(self) -> Reading:
        """Take one (averaged) reading."""

    def zero(self) -> None:
        """Run the device's dark-zero adjustment."""

    def identity(self) -> dict[str, str]:
        """The device's identity as it reports it (model, serial, firmware, sensor head...;
        {} if it reports none)."""
