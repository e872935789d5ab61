"""Driver for a Thorlabs PM100-series power meter (PM100D / PM100USB SCPI command set).

From the PM100D operation manual, "SCPI commands" chapter: messages end in LF, replies end
in LF, several message units go in one message separated by ';' (a leading ':' restarts
at the root), their answers come back joined by ';'. Errors go to the SCPI error queue
(SYST:ERR? -> `code,"message"`, 0 = none). Every exchange appends ";:SYST:ERR?" so a
device error is reported with the reply it spoiled; queries (READ?, settings) are retried
after a timeout or garble, setting commands are sent once and then checked by reading the
setting back. Numeric answers are checked against the exact shape the manual gives them
(NR3 `1.234567E-06`: sign, one digit, point, a fixed number of decimals, `E`, signed
two-digit exponent; NR1 integers; 0/1 flags): a reply with a byte lost or altered is a
ProtocolError (retried like any garbled query reply), never a plausible wrong number.
After a timeout a bare *OPC? (its `1` is the only reply without an error status)
brings late replies and requests back in step before the next exchange, so a late READ?
answer is never taken for a later reading (drivers.serial_transport).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

from drivers.base import (
    DeviceError,
    DeviceTimeout,
    DriverError,
    InvalidReading,
    ProtocolError,
    Reading,
)
from drivers.serial_transport import SerialLineTransport, SyncQuery, strict_number_parser

_ERR = re.compile(r'\s*([+-]?\d+)\s*,\s*"(.*)"\s*')
_NR1 = re.compile(r"[+-]?\d+")
NR3_DECIMALS = 6  # the PM100D manual's and the emulator's NR3: 1.234567E-06
SCPI_NAN = 9.91e37  # SCPI-99's not-a-number: the meter has no valid reading
MAX_RANGES = 32  # more ranges than any sensor has: range stepping that runs on is garbled


def nr3_parser(decimals: int = NR3_DECIMALS) -> Callable[[str], float]:
    """A strict NR3 reader: `[+-]d.<decimals digits>E[+-]dd` exactly, else ProtocolError."""
    return strict_number_parser(rf"[+-]?\d\.\d{{{int(decimals)}}}E[+-]\d\d",
                                f"NR3 like {1.0:.{int(decimals)}E}")


def _nr1(text: str) -> int:
    if _NR1.fullmatch(text) is None:
        raise ProtocolError(f"garbled integer {text!r}")
    return int(text)


def _flag(text: str) -> bool:
    if text not in ("0", "1"):
        raise ProtocolError(f"garbled flag {text!r} (expected 0 or 1)")
    return text == "1"


def _is_opc(text: str) -> bool:
    """The reply to a bare *OPC? (the sync query): 1, with no error status after it."""
    return text.strip() in ("1", "+1")


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
        nr3_decimals: int = NR3_DECIMALS,
    ):
        self.name = name
        self.zero_timeout_s = zero_timeout_s
        self._full_scales: tuple[float, ...] | None = None
        self._nr3 = nr3_parser(nr3_decimals)
        self.transport = SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\n", read_eol=b"\n",
            timeout_s=timeout_s, retries=retries, sync=SyncQuery("*OPC?", _is_opc),
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
        code, what = self._status(message, err, text)
        if code != 0:
            raise DeviceError(self.name, code, what)
        return answers

    def _status(self, message: str, err: str, text: str) -> tuple[int, str]:
        """A SYST:ERR? answer `code,"message"` as (code, message); ProtocolError if garbled.

        Code 0 and the text "No error" must come together: a lost ';' that merged an
        answer "1" into the status "0" (`10,"No error"`) is garbled, not error 10.
        """
        match = _ERR.fullmatch(err)
        if match is None or (match.group(1) in ("0", "+0")) != (
                match.group(2).lower() == "no error"):
            raise ProtocolError(f"{self.name}: garbled reply to {message!r}: {text!r}")
        return int(match.group(1)), match.group(2)

    def query(self, message: str, *parsers: Callable[[str], object]) -> list:
        """Send `message;:SYST:ERR?` and return the answers before the error status.

        parsers: one per answer (e.g. the NR3 reader), applied inside the retry loop so a
        garbled answer is re-asked; without them the answers come back as text. Retried
        after a timeout or garbled reply (use only for side-effect-free messages or ones
        that may safely run twice, such as READ?).
        """
        n_queries = message.count("?")

        def parse(text: str) -> list:
            answers = self._split(message, text)
            if len(answers) != n_queries:
                raise ProtocolError(
                    f"{self.name}: {len(answers)} answers to {message!r}, expected {n_queries}"
                )
            if not parsers:
                return answers
            try:
                return [read(answer) for read, answer in zip(parsers, answers, strict=True)]
            except ProtocolError as exc:
                raise ProtocolError(f"{self.name}: reply to {message!r}: {exc}") from None

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
            code, what = self.transport.query(
                ":SYST:ERR?", lambda t: self._status(":SYST:ERR?", t, t), "SYST:ERR?")
            if code == 0:
                break
            found.append((code, what))
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
        return self.query(":SENS:CORR:WAV?", self._nr3)[0]

    @wavelength_nm.setter
    def wavelength_nm(self, value: float) -> None:
        value = float(value)
        self.command(f":SENS:CORR:WAV {value:.10g}",
                     lambda: abs(self.wavelength_nm - value) <= 1e-6 * value)

    def wavelength_limits_nm(self) -> tuple[float, float]:
        """SENS:CORR:WAV? MIN / MAX: the sensor's wavelength range, nm."""
        lo, hi = self.query(":SENS:CORR:WAV? MIN;:SENS:CORR:WAV? MAX", self._nr3, self._nr3)
        return lo, hi

    @property
    def averaging(self) -> int:
        """SENS:AVER:COUN?: samples averaged per reading."""
        return self.query(":SENS:AVER:COUN?", _nr1)[0]

    @averaging.setter
    def averaging(self, value: int) -> None:
        self.command(f":SENS:AVER:COUN {int(value)}", lambda: self.averaging == int(value))

    @property
    def range_w(self) -> float | None:
        """The fixed range's full scale in W, or None while autoranging."""
        auto, upper = self.query(":SENS:POW:RANG:AUTO?;:SENS:POW:RANG?", _flag, self._nr3)
        return None if auto else upper

    @range_w.setter
    def range_w(self, value: float | None) -> None:
        if value is None:
            self.command(":SENS:POW:RANG:AUTO ON", lambda: self.range_w is None)
        else:
            self.command(f":SENS:POW:RANG {float(value):.6E}", lambda: self.range_w is not None)

    def full_scales_w(self) -> tuple[float, ...]:
        """The sensor's ranges (full scale, W, increasing), found once and kept: SCPI lists
        none, so the range is stepped up from SENS:POW:RANG? MIN (a set value selects the
        smallest range holding it) to MAX; the range setting is restored afterwards."""
        if self._full_scales is None:
            low, high = self.query(":SENS:POW:RANG? MIN;:SENS:POW:RANG? MAX", self._nr3,
                                   self._nr3)
            before = self.range_w
            self.range_w = low
            found = [low]
            while found[-1] < high * (1 - 1e-6):
                self.range_w = found[-1] * (1 + 1e-4)
                upper = self.range_w
                if upper is None or upper <= found[-1] or len(found) >= MAX_RANGES:
                    raise ProtocolError(f"{self.name}: range stepping from {found[-1]:g} W "
                                        f"gave {upper!r}, not a larger range")
                found.append(upper)
            self.range_w = before
            self._full_scales = tuple(found)
        return self._full_scales

    def read(self) -> Reading:
        """READ?: a new (averaged) reading, with the range it was taken on.

        saturated: the reading is above the range's full scale (over range).
        InvalidReading if the meter answers SCPI's not-a-number (9.91E+37).
        """
        power, upper = self.query(":READ?;:SENS:POW:RANG?", self._nr3, self._nr3)
        return Reading(power_w=self._valid(power, upper), range_w=upper, saturated=power > upper)

    def measure(self) -> float:
        """MEAS:POW?: configure for power and take one reading, W (InvalidReading as read)."""
        power, upper = self.query(":MEAS:POW?;:SENS:POW:RANG?", self._nr3, self._nr3)
        return self._valid(power, upper)

    def _valid(self, power: float, range_w: float) -> float:
        """The power, unless it is SCPI's not-a-number (to the NR3's precision)."""
        if abs(power - SCPI_NAN) <= 10.0 ** -NR3_DECIMALS * SCPI_NAN:
            raise InvalidReading(self.name, range_w, f"SCPI not-a-number {power:.6E}")
        return power

    def zero(self) -> None:
        """SENS:CORR:COLL:ZERO: dark-zero adjustment (cover the sensor first); waits for it."""
        self.command(":SENS:CORR:COLL:ZERO", lambda: True)
        deadline = time.monotonic() + self.zero_timeout_s
        while self.query(":SENS:CORR:COLL:ZERO:STAT?", _flag)[0]:
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, "zero adjustment", self.zero_timeout_s)
            time.sleep(0.05)

    def zero_offset_w(self) -> float:
        """SENS:CORR:COLL:ZERO:MAGN?: the dark offset the last zero measured, W."""
        return self.query(":SENS:CORR:COLL:ZERO:MAGN?", self._nr3)[0]

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

    def identity(self) -> dict[str, str]:
        """*IDN? (asked when it opened) and the sensor head's SYST:SENS:IDN? fields."""
        head = {f"sensor_{key}": str(value) for key, value in asdict(self.sensor()).items()}
        return {"idn": self.idn, **head}
