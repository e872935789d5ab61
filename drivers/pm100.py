"""Driver for a Thorlabs PM100-series power meter (PM100D / PM100USB SCPI command set).

From the PM100D operation manual, "SCPI commands" chapter: messages end in LF, replies end
in LF, several message units go in one message separated by ';' (a leading ':' restarts
at the root), their answers come back joined by ';'. Errors go to the SCPI error queue
(SYST:ERR? -> `code,"message"`, 0 = none). Every exchange appends ";:SYST:ERR?" so a
device error is reported with the reply it spoiled (drivers.status_line); queries (READ?,
settings) are retried after a timeout or garble, setting commands are sent once and, if
their status is lost, checked by reading the setting back by the rule declared with it
(drivers.settings: a fixed range must read back as that range). Numeric answers are
checked against the exact shape the manual gives them (NR3 `1.234567E-06`: sign, one
digit, point, a fixed number of decimals, `E`, signed two-digit exponent; NR1 integers;
0/1 flags): a reply with a byte lost or altered is a ProtocolError (retried like any
garbled query reply), never a plausible wrong number. After a timeout a bare *OPC? (its
`1` is the only reply without an error status) brings late replies and requests back in
step before the next exchange, so a late READ? answer is never taken for a later reading
(drivers.serial_transport).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass
from typing import Any, Unpack

from drivers.base import (
    DATA_OUT_OF_RANGE,
    DeviceError,
    InvalidReading,
    ProtocolError,
    Reading,
    WavelengthOutsideHead,
)
from drivers.byte_link import LinkOptions
from drivers.polling import poll_until
from drivers.reply_numbers import StrictNumber
from drivers.serial_transport import SerialLineTransport, SyncQuery
from drivers.settings import Setting, exactly, to_reply_precision
from drivers.status_line import StatusDialect, StatusLineDevice

_ERR = re.compile(r'\s*([+-]?\d+)\s*,\s*"(.*)"\s*')
_NR1 = re.compile(r"[+-]?\d+")
NR3_DECIMALS = 6  # the PM100D manual's and the emulator's NR3: 1.234567E-06
SCPI_NAN = 9.91e37  # SCPI-99's not-a-number: the meter has no valid reading
MAX_RANGES = 32  # more ranges than any sensor has: range stepping that runs on is garbled
ERROR_QUEUE_DEPTH = 32
ZERO_POLL_S = 0.05  # how often zero() asks whether the adjustment is still running
#: the PM100 manual's SENS:AVER:COUN: "1 sample takes approx. 3ms"; a reading's reply comes
#: that much later per averaged sample beyond the first, which its timeout adds to timeout_s
SAMPLE_S = 3e-3


def nr3_parser(decimals: int = NR3_DECIMALS) -> StrictNumber:
    """A strict NR3 reader: `[+-]d.<decimals digits>E[+-]dd` exactly, else ProtocolError."""
    return StrictNumber(rf"[+-]?\d\.\d{{{int(decimals)}}}E[+-]\d\d",
                        f"NR3 like {1.0:.{int(decimals)}E}", decimals, mantissa=True)


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


def _err_status(text: str) -> tuple[int, str] | None:
    """A SYST:ERR? answer `code,"message"` as (code, message). Code 0 and the text "No error"
    must come together: a lost ';' that merged an answer "1" into the status "0"
    (`10,"No error"`) is garbled (None), not error 10."""
    match = _ERR.fullmatch(text)
    if match is None or (match.group(1) in ("0", "+0")) != (match.group(2).lower() == "no error"):
        return None
    return int(match.group(1)), match.group(2)


def _split_err(text: str, count: int) -> tuple[list[str], str]:
    """Answers joined by ';', the SYST:ERR? answer last."""
    *answers, status = text.split(";")
    return answers, status


ERR_DIALECT = StatusDialect(suffix=";:SYST:ERR?", status_query=":SYST:ERR?", split=_split_err,
                            status=_err_status, queue_depth=ERROR_QUEUE_DEPTH)


def _fixed_or_auto(auto: bool, upper: float) -> float | None:
    """The range setting from SENS:POW:RANG:AUTO? and SENS:POW:RANG?: None while autoranging."""
    return None if auto else upper


def _range_argument(range_w: float | None) -> str:
    return ":AUTO ON" if range_w is None else f" {float(range_w):.6E}"


def _same_range(sent: float | None, got: float | None, number: StrictNumber) -> bool:
    """Autorange reads back as autorange; a fixed range as that very range (to the NR3's
    precision), not just some fixed range."""
    return got is None if sent is None else to_reply_precision(sent, got, number)


def _holds(sent: float, got: float | None, number: StrictNumber) -> bool:
    """A fixed range that holds the value sent (the meter picks the smallest that does)."""
    return got is not None and got >= sent - number.half_unit(sent)


_RANGE_QUERY = ":SENS:POW:RANG:AUTO?;:SENS:POW:RANG?"
# setting a value selects the smallest range holding it: how full_scales_w steps up the ranges
_RANGE_HOLDING = Setting(_RANGE_QUERY, ":SENS:POW:RANG {}", ("flag", "number"), "{:.6E}".format,
                         _holds, "the smallest fixed range holding a power, W",
                         value=_fixed_or_auto)


@dataclass(frozen=True)
class SensorIdentity:
    """SYST:SENS:IDN?: the connected sensor head."""

    name: str
    serial: str
    calibration: str
    type: int
    subtype: int
    flags: int


class Pm100(StatusLineDevice):
    """A PM100-series meter as the engine's Detector (power in W), on a serial port or, by
    `resource`, a VISA resource (a PM100USB's USB-TMC, ASRL, TCPIP SOCKET; LinkOptions)."""

    dialect = ERR_DIALECT
    integer = staticmethod(_nr1)
    flag = staticmethod(_flag)

    wavelength_nm = Setting(":SENS:CORR:WAV?", ":SENS:CORR:WAV {}", "number", "{:.10g}".format,
                            to_reply_precision, "SENS:CORR:WAV: correction wavelength, nm")
    averaging = Setting(":SENS:AVER:COUN?", ":SENS:AVER:COUN {}", "integer",
                        lambda count: str(int(count)), exactly,
                        "SENS:AVER:COUN: samples averaged per reading")
    range_w = Setting(_RANGE_QUERY, ":SENS:POW:RANG{}", ("flag", "number"), _range_argument,
                      _same_range, "the fixed range's full scale, W, or None while autoranging",
                      value=_fixed_or_auto)

    def __init__(self, port: str | None = None, baudrate: int = 115200, timeout_s: float = 1.0,
                 name: str = "pm100", retries: int = 2, zero_timeout_s: float = 10.0,
                 nr3_decimals: int = NR3_DECIMALS, **link: Unpack[LinkOptions]):
        self.zero_timeout_s = zero_timeout_s
        self._full_scales: tuple[float, ...] | None = None
        self._samples = 1  # the averaging the meter holds (read on opening, kept on writes)
        self.number = nr3_parser(nr3_decimals)
        super().__init__(name, SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\n", read_eol=b"\n",
            timeout_s=timeout_s, retries=retries, sync=SyncQuery("*OPC?", _is_opc), **link,
        ))
        try:
            self.errors()  # start from an empty error queue
            self.idn = self.query("*IDN?")[0]
            self.query(":CONF:POW")
            self._samples = int(self.averaging)
        except BaseException:  # a Ctrl-C too: a long-lived process must not keep the port
            self.close()
            raise

    # -- exchanges --------------------------------------------------------------
    def query(self, message: str, *parsers: Callable[[str], Any]) -> list:
        """Send `message;:SYST:ERR?` and return the answers before the error status.

        parsers: one per answer (e.g. the NR3 reader), applied inside the retry loop so a
        garbled answer is re-asked; without them the answers come back as text. Retried
        after a timeout or garbled reply (use only for side-effect-free messages or ones
        that may safely run twice, such as READ?).
        """
        return self.query_answers(message, parsers, message.count("?"))

    # -- Detector interface -------------------------------------------------------
    def configure(self, wavelength_nm: float, averaging: int, range_w: float | None) -> None:
        """Set the correction wavelength, averaged samples and a fixed range (None = auto);
        a wavelength the sensor head cannot take is a WavelengthOutsideHead."""
        if isinstance(averaging, bool) or int(averaging) != averaging or averaging < 1:
            raise ValueError(f"{self.name}: averaging must be an integer >= 1, got {averaging!r}")
        self._set_wavelength(wavelength_nm)
        self.averaging = averaging
        self.range_w = range_w

    def _set_wavelength(self, wavelength_nm: float) -> None:
        """SENS:CORR:WAV; when the meter refuses it as out of range and the head's range
        (SENS:CORR:WAV? MIN / MAX) does not hold it, the error names the head and its range."""
        try:
            self.wavelength_nm = wavelength_nm
        except DeviceError as exc:
            outside = exc.code == DATA_OUT_OF_RANGE and WavelengthOutsideHead.asked(
                self, wavelength_nm)
            if not outside:
                raise
            raise outside from None

    def wavelength_limits_nm(self) -> tuple[float, float]:
        """SENS:CORR:WAV? MIN / MAX: the sensor's wavelength range, nm."""
        lo, hi = self.query(":SENS:CORR:WAV? MIN;:SENS:CORR:WAV? MAX", self.number, self.number)
        return lo, hi

    def head_name(self) -> str:
        """The connected sensor head's name, as SYST:SENS:IDN? gives it (S121C)."""
        return self.sensor().name

    def full_scales_w(self) -> tuple[float, ...]:
        """The sensor's ranges (full scale, W, increasing), found once and kept: SCPI lists
        none, so the range is stepped up from SENS:POW:RANG? MIN (a set value selects the
        smallest range holding it) to MAX; the range setting is restored afterwards."""
        if self._full_scales is None:
            low, high = self.query(":SENS:POW:RANG? MIN;:SENS:POW:RANG? MAX", self.number,
                                   self.number)
            before = self.range_w
            self.range_w = low
            found = [low]
            while found[-1] < high * (1 - 1e-6):
                self.write_setting(_RANGE_HOLDING, found[-1] * (1 + 1e-4))
                upper = self.range_w
                if upper is None or upper <= found[-1] or len(found) >= MAX_RANGES:
                    raise ProtocolError(f"{self.name}: range stepping from {found[-1]:g} W "
                                        f"gave {upper!r}, not a larger range")
                found.append(upper)
            self.range_w = before
            self._full_scales = tuple(found)
        return self._full_scales

    def write_setting(self, setting: Setting, value: Any, address: str = "") -> None:
        """As StatusLineDevice's, keeping the averaging written (a reading's time)."""
        super().write_setting(setting, value, address)
        if setting is Pm100.averaging:
            self._samples = int(value)

    def _sampling(self) -> AbstractContextManager[None]:
        """The transport waiting for a reading's reply the time its averaged samples beyond
        the first take (SAMPLE_S each) longer: timeout_s is a one-sample reading's."""
        return self.transport.longer_replies((self._samples - 1) * SAMPLE_S)

    def read(self) -> Reading:
        """READ?: a new (averaged) reading, with the range it was taken on.

        saturated: the reading is above the range's full scale (over range).
        InvalidReading if the meter answers SCPI's not-a-number (9.91E+37).
        """
        with self._sampling():
            power, upper = self.query(":READ?;:SENS:POW:RANG?", self.number, self.number)
        return Reading(power_w=self._valid(power, upper), range_w=upper, saturated=power > upper)

    def measure(self) -> float:
        """MEAS:POW?: configure for power and take one reading, W (InvalidReading as read)."""
        with self._sampling():
            power, upper = self.query(":MEAS:POW?;:SENS:POW:RANG?", self.number, self.number)
        return self._valid(power, upper)

    def _valid(self, power: float, range_w: float) -> float:
        """The power, unless it is SCPI's not-a-number (to the NR3's precision)."""
        if abs(power - SCPI_NAN) <= 10.0 ** -NR3_DECIMALS * SCPI_NAN:
            raise InvalidReading(self.name, range_w, f"SCPI not-a-number {power:.6E}")
        return power

    def zero(self) -> None:
        """SENS:CORR:COLL:ZERO: dark-zero adjustment (cover the sensor first); waits for it."""
        self.command(":SENS:CORR:COLL:ZERO", lambda: True)
        poll_until(lambda: None if self.query(":SENS:CORR:COLL:ZERO:STAT?", _flag)[0] else True,
                   self.zero_timeout_s, ZERO_POLL_S, self.name, "zero adjustment")

    def zero_offset_w(self) -> float:
        """SENS:CORR:COLL:ZERO:MAGN?: the dark offset the last zero measured, W."""
        return self.query(":SENS:CORR:COLL:ZERO:MAGN?", self.number)[0]

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
