"""Driver for a Thorlabs PM100-series power meter (PM100D / PM100USB SCPI command set).

From the PM100D operation manual, "SCPI commands" chapter: messages end in LF, replies end
in LF, several message units go in one message separated by ';' (a leading ':' restarts
at the root), their answers come back joined by ';'. Errors go to the SCPI error queue
(SYST:ERR? -> `code,"message"`, 0 = none). Every exchange appends ";:SYST:ERR?" so a
device error is reported with the reply it spoiled; queries (READ?, settings) are retried
after a timeout or garble, setting commands are sent once and then checked by reading the
setting back.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass

from drivers.base import DeviceError, DeviceTimeout, DriverError, ProtocolError, Reading
from drivers.serial_transport import SerialLineTransport

_ERR = re.compile(r'\s*([+-]?\d+)\s*,\s*"(.*)"\s*')


def _float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ProtocolError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ProtocolError(f"expected a finite number, got {text!r}")
    return value


@dataclass(frozen=True)
class SensorIdentity:
    """SYST:SENS:IDN?: the connected sensor head."""

    name: str
    serial: str
    calibration: str
    type: int
    subtype: int
    flags: int


class Pm100:
    """A PM100-series meter as the engine's Detector (power in W)."""

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        name: str = "pm100",
        retries: int = 2,
        zero_timeout_s: float = 10.0,
    ):
        self.name = name
        self.zero_timeout_s = zero_timeout_s
        self.transport = SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\n", read_eol=b"\n",
            timeout_s=timeout_s, retries=retries,
        )
        try:
            self.errors()  # start from an empty error queue
            self.idn = self.query("*IDN?")[0]
            self.query(":CONF:POW")
        except DriverError:
            self.transport.close()
            raise

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Close the serial port."""
        self.transport.close()

    def __enter__(self) -> Pm100:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- exchanges --------------------------------------------------------------
    def _split(self, message: str, text: str) -> list[str]:
        """Answers before the trailing SYST:ERR? one; DeviceError if it reports one."""
        *answers, err = text.split(";")
        match = _ERR.fullmatch(err)
        if match is None:
            raise ProtocolError(f"{self.name}: garbled reply to {message!r}: {text!r}")
        code = int(match.group(1))
        if code != 0:
            raise DeviceError(self.name, code, match.group(2))
        return answers

    def query(self, message: str) -> list[str]:
        """Send `message;:SYST:ERR?` and return the answers before the error status.

        Retried after a timeout or garbled reply (use only for side-effect-free messages
        or ones that may safely run twice, such as READ?).
        """
        n_queries = message.count("?")

        def parse(text: str) -> list[str]:
            answers = self._split(message, text)
            if len(answers) != n_queries:
                raise ProtocolError(
                    f"{self.name}: {len(answers)} answers to {message!r}, expected {n_queries}"
                )
            return answers

        return self.transport.query(f"{message};:SYST:ERR?", parse, message)

    def command(self, message: str, check: Callable[[], bool]) -> None:
        """Send a setting command once; if its status is lost, `check()` re-reads the setting."""
        try:
            self._split(message, self.transport.exchange(f"{message};:SYST:ERR?", message))
        except (DeviceTimeout, ProtocolError) as exc:
            self.errors(raise_first=True)
            if not check():
                raise DriverError(
                    f"{self.name}: {message!r} not confirmed ({exc}); not re-sent"
                ) from exc

    def errors(self, raise_first: bool = False) -> list[tuple[int, str]]:
        """Drain the SCPI error queue; raise_first raises DeviceError for the first one."""
        found = []
        for _ in range(32):
            text = self.transport.query(":SYST:ERR?", lambda t: t, "SYST:ERR?")
            match = _ERR.fullmatch(text)
            if match is None:
                raise ProtocolError(f"{self.name}: garbled SYST:ERR? reply {text!r}")
            if int(match.group(1)) == 0:
                break
            found.append((int(match.group(1)), match.group(2)))
        if raise_first and found:
            raise DeviceError(self.name, *found[0])
        return found

    # -- Detector interface -------------------------------------------------------
    def configure(self, wavelength_nm: float, averaging: int, range_w: float | None) -> None:
        """Set the correction wavelength, averaged samples and a fixed range (None = auto)."""
        if isinstance(averaging, bool) or int(averaging) != averaging or averaging < 1:
            raise ValueError(f"{self.name}: averaging must be an integer >= 1, got {averaging!r}")
        self.wavelength_nm = wavelength_nm
        self.averaging = averaging
        self.range_w = range_w

    @property
    def wavelength_nm(self) -> float:
        """SENS:CORR:WAV?: correction wavelength, nm."""
        return _float(self.query(":SENS:CORR:WAV?")[0])

    @wavelength_nm.setter
    def wavelength_nm(self, value: float) -> None:
        value = float(value)
        self.command(f":SENS:CORR:WAV {value:.10g}",
                     lambda: abs(self.wavelength_nm - value) <= 1e-6 * value)

    def wavelength_limits_nm(self) -> tuple[float, float]:
        """SENS:CORR:WAV? MIN / MAX: the sensor's wavelength range, nm."""
        lo, hi = self.query(":SENS:CORR:WAV? MIN;:SENS:CORR:WAV? MAX")
        return _float(lo), _float(hi)

    @property
    def averaging(self) -> int:
        """SENS:AVER:COUN?: samples averaged per reading."""
        return int(_float(self.query(":SENS:AVER:COUN?")[0]))

    @averaging.setter
    def averaging(self, value: int) -> None:
        self.command(f":SENS:AVER:COUN {int(value)}", lambda: self.averaging == int(value))

    @property
    def range_w(self) -> float | None:
        """The fixed range's full scale in W, or None while autoranging."""
        auto, upper = self.query(":SENS:POW:RANG:AUTO?;:SENS:POW:RANG?")
        return None if auto.strip() == "1" else _float(upper)

    @range_w.setter
    def range_w(self, value: float | None) -> None:
        if value is None:
            self.command(":SENS:POW:RANG:AUTO ON", lambda: self.range_w is None)
        else:
            self.command(f":SENS:POW:RANG {float(value):.6E}", lambda: self.range_w is not None)

    def read(self) -> Reading:
        """READ?: a new (averaged) reading, with the range it was taken on.

        saturated: the reading is above the range's full scale (over range).
        """
        power, upper = (_float(v) for v in self.query(":READ?;:SENS:POW:RANG?"))
        return Reading(power_w=power, range_w=upper, saturated=power > upper)

    def measure(self) -> float:
        """MEAS:POW?: configure for power and take one reading, W."""
        return _float(self.query(":MEAS:POW?")[0])

    def zero(self) -> None:
        """SENS:CORR:COLL:ZERO: dark-zero adjustment (cover the sensor first); waits for it."""
        self.command(":SENS:CORR:COLL:ZERO", lambda: True)
        deadline = time.monotonic() + self.zero_timeout_s
        while self.query(":SENS:CORR:COLL:ZERO:STAT?")[0].strip() != "0":
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, "zero adjustment", self.zero_timeout_s)
            time.sleep(0.05)

    def zero_offset_w(self) -> float:
        """SENS:CORR:COLL:ZERO:MAGN?: the dark offset the last zero measured, W."""
        return _float(self.query(":SENS:CORR:COLL:ZERO:MAGN?")[0])

    def sensor(self) -> SensorIdentity:
        """SYST:SENS:IDN?: name, serial number, calibration message, type, subtype, flags."""
        fields = self.query(":SYST:SENS:IDN?")[0].split(",")
        if len(fields) != 6:
            raise ProtocolError(f"{self.name}: SYST:SENS:IDN? gave {len(fields)} fields, not 6")
        try:
            kind, subtype, flags = (int(f) for f in fields[3:])
        except ValueError:
            raise ProtocolError(f"{self.name}: bad SYST:SENS:IDN? reply {fields!r}") from None
        return SensorIdentity(*(f.strip() for f in fields[:3]), kind, subtype, flags)
