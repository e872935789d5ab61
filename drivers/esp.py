"""Driver for the Newport ESP300/ESP301 motion controller (RS-232 ASCII command set).

Byte-level details from the ESP301 user's manual (EDH0235En1030, section 3): a command
is `[axis]XX[parameter]` ended by CR (we send CR), replies end in CR LF, commands are
silent and errors go to a FIFO read with TB? ("code, timestamp, MESSAGE"; axis errors are
axis*100 + code). Every exchange appends ";TB?" so the error status comes back with it
(queries on one line answer on one line, comma-separated: drivers.status_line). Queries
are retried after a timeout or garble; a state-changing command is sent once, and if its
status reply is lost the driver re-reads the device state (error buffer, then the setting,
by the check declared with it: drivers.settings) instead of re-sending it. An emergency stop
(the E-stop input: the controller stops the axes and, as configured by ZE, switches their
motors off) is error 4, EMERGENCY STOP ACTIVATED, in that buffer: the driver raises
Interlocked for it, and `EspAxis.release_interlock` gets the axis ready again once the input
is released. Numeric replies must have the controller's fixed shape (optional minus, digits,
point, DECIMALS decimals, as in `-12.50000`); any other shape is a garbled reply (retried),
and a setting read back matches to that precision. After a timeout a bare VE? (its reply is
the only one without an error status) brings late replies and requests back in step before
the next exchange (drivers.serial_transport).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any, TypeVar, Unpack

from drivers.base import DeviceError, Interlocked, ProtocolError
from drivers.byte_link import LinkOptions
from drivers.polling import poll_until
from drivers.reply_numbers import StrictNumber
from drivers.serial_transport import SerialLineTransport, SyncQuery
from drivers.settings import Setting, exactly, to_reply_precision
from drivers.status_line import StatusDialect, StatusLineDevice

T = TypeVar("T")
_TB = re.compile(r"\s*(\d+)\s*,\s*(\d+)\s*,\s*(.*\S)\s*")
_INTEGER = re.compile(r"\d+")
DECIMALS = 5  # the ESP301's (and the emulator's) position and rate replies: 12.50000
EMERGENCY_STOP = 4  # general error EMERGENCY STOP ACTIVATED: the E-stop input stopped the axes
ERROR_BUFFER_DEPTH = 10


def decimal_parser(decimals: int = DECIMALS) -> StrictNumber:
    """A strict reader of the ESP's fixed-point replies (`-?digits.<decimals digits>`)."""
    return StrictNumber(rf"-?\d+\.\d{{{int(decimals)}}}", f"{0:.{int(decimals)}f} form",
                        decimals)


def _integer(text: str) -> int:
    if _INTEGER.fullmatch(text) is None:
        raise ProtocolError(f"garbled integer {text!r}")
    return int(text)


def _flag(text: str) -> bool:
    if text.strip() not in ("0", "1"):
        raise ProtocolError(f"expected 0 or 1, got {text!r}")
    return text.strip() == "1"


def _fmt(value: float) -> str:
    """A number as the ESP reads it (plain decimal, enough digits)."""
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {value!r}")
    return format(float(value), ".10g")


def _tb_status(text: str) -> tuple[int, str] | None:
    """TB? as (code, message). Code 0 and NO ERROR DETECTED must come together: a lost ','
    that merged an answer "1" into the status "0" (`10, ...NO ERROR...`) is garbled (None),
    not error 10."""
    match = _TB.fullmatch(text)
    if match is None or (match.group(1) == "0") != (match.group(3) == "NO ERROR DETECTED"):
        return None
    return int(match.group(1)), match.group(3)


def _split_tb(text: str, count: int) -> tuple[list[str], str]:
    """Answers joined by commas, then TB?'s three fields. Only the first answer may contain
    commas (a version string), so a lost or extra comma between answers breaks the count."""
    parts = text.rsplit(",", count + 2)
    return [answer.strip() for answer in parts[:-3]], ",".join(parts[-3:])


TB_DIALECT = StatusDialect(suffix=";TB?", status_query="TB?", split=_split_tb,
                           status=_tb_status, queue_depth=ERROR_BUFFER_DEPTH,
                           interlocks=(EMERGENCY_STOP,))


class EspController(StatusLineDevice):
    """One ESP300/ESP301 on a serial port (or, by `resource`, a VISA resource: LinkOptions);
    `axis(n, name)` gives engine-facing Axis objects.

    timeout_s bounds every reply; retries is how often a query is re-asked; poll_s is how
    often wait() asks MD?; rtscts: the ESP's RS-232 port (19200 8N1) uses RTS/CTS
    hardware handshake; decimals: how many decimals its numeric replies carry.
    """

    dialect = TB_DIALECT
    integer = staticmethod(_integer)
    flag = staticmethod(_flag)

    def __init__(self, port: str | None = None, baudrate: int = 19200, timeout_s: float = 1.0,
                 name: str = "esp", retries: int = 2, poll_s: float = 0.01, rtscts: bool = True,
                 decimals: int = DECIMALS, **link: Unpack[LinkOptions]):
        self.poll_s = poll_s
        self.number = decimal_parser(decimals)
        self.version: str | None = None
        super().__init__(name, SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\r", read_eol=b"\r\n",
            timeout_s=timeout_s, retries=retries, rtscts=rtscts,
            sync=SyncQuery("VE?", self._is_version), **link,
        ))
        try:
            self.errors()  # start from an empty error buffer
            self.version = self.query("VE?")
        except BaseException:  # a Ctrl-C too: a long-lived process must not keep the port
            self.close()
            raise

    def _is_version(self, text: str) -> bool:
        """The reply to a bare VE? (the sync query): the version string (once known, exactly
        it), never followed by an error status as the replies to every other exchange are."""
        if self.version is not None:
            return text == self.version
        return "VERSION" in text.upper() and _tb_status(",".join(text.split(",")[-3:])) is None

    def query(self, line: str, parse: Callable[[str], T] = str) -> T:
        """Ask a query with ";TB?" appended, so its error status comes in the same reply.

        Retried on timeout or garble; a device error raises DeviceError (not retried).
        """
        return self.query_answers(line, (parse,), 1)[0]

    def query_values(self, line: str, *parsers: Callable[[str], Any]) -> list:
        """Ask several queries on one line (`1MD?;1TP?`, one parser per answer) with ";TB?"
        appended: one round trip for all of them, answered in order on one line, joined by
        commas."""
        return self.query_answers(line, parsers, len(parsers))

    def identity(self) -> dict[str, str]:
        """The controller's VE? reply (model and firmware version), asked when it opened."""
        return {"version": self.version}

    def abort(self) -> None:
        """AB: stop every axis at once (no deceleration)."""
        self.command("AB")

    def axis(self, number: int, name: str | None = None, enable: bool = True) -> EspAxis:
        """The Axis object for axis `number` (1..9); enable=True switches its motor on."""
        if not (isinstance(number, int) and 1 <= number <= 9):
            raise ValueError(f"{self.name}: axis number must be 1..9, got {number!r}")
        axis = EspAxis(self, number, name or f"{self.name}.{number}")
        if enable:
            axis.enable()
        return axis


DEGREES = 7  # SN7: the stage's units are degrees
# settings: query, command, reply reader, value format, read-back check, what it is
_TARGET = Setting("PA?", "PA{}", "number", _fmt, to_reply_precision, "PA: move target, deg")
_LOW_LIMIT = Setting("SL?", "SL{}", "number", _fmt, to_reply_precision, "SL: left limit, deg")
_HIGH_LIMIT = Setting("SR?", "SR{}", "number", _fmt, to_reply_precision, "SR: right limit, deg")
_UNITS = Setting("SN?", "SN{}", "integer", str, exactly, "SN: displacement units, 7 = degrees")


def _motor(on: bool) -> str:
    return "MO" if on else "MF"


class EspAxis:
    """One ESP axis as the engine's Axis (degrees; the stage's units are set to degrees)."""

    speed_deg_s = Setting("VA?", "VA{}", "number", _fmt, to_reply_precision, "VA: speed, deg/s")
    accel_deg_s2 = Setting("AC?", "AC{}", "number", _fmt, to_reply_precision, "AC: accel deg/s2")
    decel_deg_s2 = Setting("AG?", "AG{}", "number", _fmt, to_reply_precision, "AG: decel deg/s2")
    enabled = Setting("MO?", "{}", "flag", _motor, exactly, "MO?: motor on (MO: on, MF: off)")

    def __init__(self, controller: EspController, number: int, name: str):
        self.controller, self.number, self.name = controller, number, name
        self._p = str(number)

    def read_setting(self, setting: Setting) -> Any:
        """A setting of this axis (its number before the query)."""
        return self.controller.read_setting(setting, self._p)

    def write_setting(self, setting: Setting, value: Any) -> None:
        """Set a setting of this axis once, read back by its check if the status is lost."""
        self.controller.write_setting(setting, value, self._p)

    def _query(self, cmd: str, parse: Callable[[str], T] | None = None) -> T:
        """An axis query; numeric (the controller's fixed-point shape) unless parse is given."""
        return self.controller.query(self._p + cmd, parse or self.controller.number)

    def _command(self, cmd: str, verify: Callable[[], bool] | None = None) -> None:
        self.controller.command(self._p + cmd, verify)

    # -- Axis interface ---------------------------------------------------------
    def configure(self, speed_deg_s: float, accel_deg_s2: float,
                  limits_deg: tuple[float, float]) -> None:
        """VA, AC, then SL/SR: the next moves' speed and acceleration, the travel limits."""
        self.speed_deg_s = speed_deg_s
        self.accel_deg_s2 = accel_deg_s2
        self.limits_deg = limits_deg

    def move_to(self, position_deg: float) -> None:
        """PA: start an absolute move (returns at once)."""
        self.write_setting(_TARGET, float(position_deg))

    def move_by(self, delta_deg: float) -> None:
        """PR: start a move relative to the current target. A lost status is settled by the
        target read back within one unit of its last place of the goal (the goal itself comes
        from a target read to half a unit)."""
        goal = self.target() + float(delta_deg)
        unit = 2 * self.controller.number.half_unit(goal)
        self._command(f"PR{_fmt(delta_deg)}", lambda: abs(self.target() - goal) <= unit)

    def position(self) -> float:
        """TP?: actual position, degrees."""
        return self._query("TP?")

    def target(self) -> float:
        """PA?: the position the current (or last) move goes to."""
        return self.read_setting(_TARGET)

    def is_moving(self) -> bool:
        """MD?: 0 while a move or home is under way."""
        return not self._query("MD?", _flag)

    def wait(self, timeout_s: float) -> float:
        """Poll motion done and position together (`nMD?;nTP?`, one round trip) until the
        device reports the motion done; returns the position it reported with that status
        (read after it, so the final one). DeviceTimeout after timeout_s."""
        def done_at() -> float | None:
            done, position = self.controller.query_values(
                f"{self._p}MD?;{self._p}TP?", _flag, self.controller.number)
            return position if done else None

        return poll_until(done_at, timeout_s, self.controller.poll_s, self.name,
                          "motion done (MD?)")

    def stop(self) -> None:
        """ST: decelerate to a stop; safe at any time (the HOMING ABORTED a stop during a
        home search reports is the expected outcome, not a failure)."""
        try:
            self._command("ST")
        except DeviceError as exc:
            if exc.code != self.number * 100 + 20:
                raise

    def home(self) -> None:
        """OR: start a home search."""
        self._command("OR")

    def release_interlock(self) -> str | None:
        """After an emergency stop (Interlocked): drop the errors it left in the buffer and
        switch the motor on again (MO); what still holds it (the E-stop input still asserted:
        MO refused with EMERGENCY STOP ACTIVATED), or None once the axis is ready."""
        try:
            self.controller.errors()
            self.enable()
        except Interlocked as exc:
            return str(exc)
        return None

    def identity(self) -> dict[str, str]:
        """The controller's identity (every axis of one ESP reports the same)."""
        return self.controller.identity()

    def line_counts(self) -> dict[str, int]:
        """What the controller's line has seen (drivers.base.LineCounts)."""
        return self.controller.line_counts()

    def define_position(self, position_deg: float = 0.0) -> None:
        """DH: call the current position `position_deg` (defines home)."""
        self._command(f"DH{_fmt(position_deg)}")

    # -- settings ---------------------------------------------------------------
    def enable(self) -> None:
        """MO: motor on, units degrees (SN7)."""
        self.enabled = True
        self.write_setting(_UNITS, DEGREES)

    def disable(self) -> None:
        """MF: motor off."""
        self.enabled = False

    @property
    def limits_deg(self) -> tuple[float, float]:
        """(SL?, SR?): software travel limits."""
        return self.read_setting(_LOW_LIMIT), self.read_setting(_HIGH_LIMIT)

    @limits_deg.setter
    def limits_deg(self, value: tuple[float, float]) -> None:
        lo, hi = float(value[0]), float(value[1])
        if not lo < hi:
            raise ValueError(f"{self.name}: limits must be (lo, hi) with lo < hi, got {value!r}")
        cur_lo, _ = self.limits_deg
        # order the two commands so the pair stays valid (SL < SR) in between
        order = ((_HIGH_LIMIT, hi), (_LOW_LIMIT, lo)) if lo >= cur_lo else \
            ((_LOW_LIMIT, lo), (_HIGH_LIMIT, hi))
        for setting, limit in order:
            self.write_setting(setting, limit)
