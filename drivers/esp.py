"""Driver for the Newport ESP300/ESP301 motion controller (RS-232 ASCII command set).

Byte-level details from the ESP301 user's manual (EDH0235En1030, section 3): a command is
`[axis]XX[parameter]` ended by CR (we send CR), replies end in CR LF, commands are silent and
errors go to a FIFO read with TB? ("code, timestamp, MESSAGE"; axis errors are axis*100 +
code). Every exchange appends ";TB?" so the error status comes back with it (queries on one
line answer on one line, comma-separated). Queries are retried after a timeout or garble; a
state-changing command is sent once, and if its status reply is lost the driver re-reads the
device state (error buffer, target) instead of re-sending it. An emergency stop (the E-stop
input: the controller stops the axes and, as configured by ZE, switches their motors off) is
error 4, EMERGENCY STOP ACTIVATED, in that buffer: the driver raises Interlocked for it, and
`EspAxis.release_interlock` gets the axis ready again once the input is released. Numeric
replies must have the controller's fixed shape (optional minus, digits, point, DECIMALS
decimals, as in `-12.50000`); any other shape is a garbled reply (retried). After a timeout a
bare VE? (its reply is the only one without an error status) brings late replies and requests
back in step before the next exchange (drivers.serial_transport).
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from typing import TypeVar

from drivers.base import DeviceError, DeviceTimeout, DriverError, Interlocked, ProtocolError
from drivers.serial_transport import SerialLineTransport, SyncQuery, strict_number_parser

T = TypeVar("T")
_TB = re.compile(r"\s*(\d+)\s*,\s*(\d+)\s*,\s*(.*\S)\s*")
_INTEGER = re.compile(r"\d+")
DECIMALS = 5  # the ESP301's (and the emulator's) position and rate replies: 12.50000
EMERGENCY_STOP = 4  # general error EMERGENCY STOP ACTIVATED: the E-stop input stopped the axes


def decimal_parser(decimals: int = DECIMALS) -> Callable[[str], float]:
    """A strict reader of the ESP's fixed-point replies (`-?digits.<decimals digits>`)."""
    return strict_number_parser(rf"-?\d+\.\d{{{int(decimals)}}}",
                                f"{0:.{int(decimals)}f} form")


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


class EspController:
    """One ESP300/ESP301 on a serial port; `axis(n, name)` gives engine-facing Axis objects.

    timeout_s bounds every reply; retries is how often a query is re-asked; poll_s is how
    often wait() asks MD?; rtscts: the ESP's RS-232 port (19200 8N1) uses RTS/CTS
    hardware handshake; decimals: how many decimals its numeric replies carry.
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 19200,
        timeout_s: float = 1.0,
        name: str = "esp",
        retries: int = 2,
        poll_s: float = 0.01,
        rtscts: bool = True,
        decimals: int = DECIMALS,
    ):
        self.name = name
        self.poll_s = poll_s
        self.number = decimal_parser(decimals)
        self.version: str | None = None
        self.transport = SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\r", read_eol=b"\r\n",
            timeout_s=timeout_s, retries=retries, rtscts=rtscts,
            sync=SyncQuery("VE?", self._is_version),
        )
        try:
            self.errors()  # start from an empty error buffer
            self.version = self.query("VE?")
        except DriverError:
            self.transport.close()
            raise

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Close the serial port."""
        self.transport.close()

    def __enter__(self) -> EspController:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _is_version(self, text: str) -> bool:
        """The reply to a bare VE? (the sync query): the version string (once known, exactly
        it), never followed by an error status as the replies to every other exchange are."""
        if self.version is not None:
            return text == self.version
        return "VERSION" in text.upper() and _TB.fullmatch(",".join(text.split(",")[-3:])) is None

    # -- error buffer -----------------------------------------------------------
    def _parse_tb(self, text: str) -> tuple[int, str]:
        """TB? as (code, message). Code 0 and NO ERROR DETECTED must come together: a
        lost ',' that merged an answer "1" into the status "0" (`10, ...NO ERROR...`) is
        garbled, not error 10."""
        match = _TB.fullmatch(text)
        if match is None or (match.group(1) == "0") != (match.group(3) == "NO ERROR DETECTED"):
            raise ProtocolError(f"{self.name}: garbled TB? reply {text!r}")
        return int(match.group(1)), match.group(3)

    def next_error(self) -> tuple[int, str]:
        """Pop the oldest buffered error: (code, message); (0, ...) when empty."""
        return self.transport.query("TB?", self._parse_tb, "TB? (error buffer)")

    def errors(self) -> list[tuple[int, str]]:
        """Drain the error buffer (at most its 10 entries)."""
        found = []
        for _ in range(10):
            code, text = self.next_error()
            if code == 0:
                break
            found.append((code, text))
        return found

    def _raise_if_error(self, code: int, text: str) -> None:
        if code == EMERGENCY_STOP:
            raise Interlocked(self.name, code, text)
        if code != 0:
            raise DeviceError(self.name, code, text)

    def query(self, line: str, parse: Callable[[str], T] = str) -> T:
        """Ask a query with ";TB?" appended, so its error status comes in the same reply.

        Retried on timeout or garble; a device error raises DeviceError (not retried).
        """
        return self.query_values(line, parse)[0]

    def query_values(self, line: str, *parsers: Callable[[str], object]) -> list:
        """Ask several queries on one line (`1MD?;1TP?`, one parser per answer) with ";TB?"
        appended: one round trip for all of them, answered in order on one line, joined by
        commas. Only the first answer may contain commas (a version string), so a lost or
        extra comma between answers breaks the count: a garbled reply (retried), not a
        misread one."""
        n = len(parsers)

        def checked(text: str) -> list:
            parts = text.rsplit(",", n + 2)
            code, message = self._parse_tb(",".join(parts[-3:]))
            self._raise_if_error(code, message)
            if len(parts) != n + 3:
                raise ProtocolError(f"{self.name}: {len(parts) - 3} answers to {line!r}, "
                                    f"expected {n}: {text!r}")
            try:
                return [parse(answer.strip()) for parse, answer in zip(parsers, parts[:n],
                                                                       strict=True)]
            except ProtocolError as exc:
                raise ProtocolError(f"{self.name}: reply to {line!r}: {exc}") from None

        return self.transport.query(f"{line};TB?", checked, line)

    def command(self, line: str, verify: Callable[[], bool] | None = None) -> None:
        """Send a state-changing command once, with its error status in the same exchange.

        If the status reply is lost or garbled, the error buffer is re-read and `verify()`
        (if given) checks the device state; the command itself is never re-sent.
        """
        try:
            reply = self.transport.exchange(f"{line};TB?", f"{line!r} status")
            code, text = self._parse_tb(reply)
        except (DeviceTimeout, ProtocolError) as exc:
            self._raise_if_error(*self.next_error())
            if verify is None or not verify():
                raise DriverError(
                    f"{self.name}: {line!r} not confirmed ({exc}); not re-sent"
                ) from exc
            return
        self._raise_if_error(code, text)

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


class EspAxis:
    """One ESP axis as the engine's Axis (degrees; the stage's units are set to degrees)."""

    def __init__(self, controller: EspController, number: int, name: str):
        self.controller, self.number, self.name = controller, number, name
        self._p = str(number)

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
        target = float(position_deg)
        self._command(f"PA{_fmt(target)}", lambda: abs(self.target() - target) < 1e-4)

    def move_by(self, delta_deg: float) -> None:
        """PR: start a move relative to the current target."""
        goal = self.target() + float(delta_deg)
        self._command(f"PR{_fmt(delta_deg)}", lambda: abs(self.target() - goal) < 1e-4)

    def position(self) -> float:
        """TP?: actual position, degrees."""
        return self._query("TP?")

    def target(self) -> float:
        """PA?: the position the current (or last) move goes to."""
        return self._query("PA?")

    def is_moving(self) -> bool:
        """MD?: 0 while a move or home is under way."""
        return not self._query("MD?", _flag)

    def wait(self, timeout_s: float) -> float:
        """Poll motion done and position together (`nMD?;nTP?`, one round trip) until the
        device reports the motion done; returns the position it reported with that status
        (read after it, so the final one). DeviceTimeout after timeout_s."""
        deadline = time.monotonic() + timeout_s
        while True:
            done, position = self.controller.query_values(
                f"{self._p}MD?;{self._p}TP?", _flag, self.controller.number)
            if done:
                return position
            if time.monotonic() > deadline:
                raise DeviceTimeout(self.name, "motion done (MD?)", timeout_s)
            time.sleep(self.controller.poll_s)

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

    def define_position(self, position_deg: float = 0.0) -> None:
        """DH: call the current position `position_deg` (defines home)."""
        self._command(f"DH{_fmt(position_deg)}")

    # -- settings ---------------------------------------------------------------
    def enable(self) -> None:
        """MO: motor on, units degrees (SN7)."""
        self._command("MO", lambda: self.enabled)
        self._command("SN7", lambda: self._query("SN?", _integer) == 7)

    def disable(self) -> None:
        """MF: motor off."""
        self._command("MF", lambda: not self.enabled)

    @property
    def enabled(self) -> bool:
        """MO?: motor on."""
        return self._query("MO?", _flag)

    def _setting(self, cmd: str, value: float) -> None:
        self._command(f"{cmd}{_fmt(value)}", lambda: abs(self._query(f"{cmd}?") - value) < 1e-6)

    @property
    def speed_deg_s(self) -> float:
        """VA?: velocity of the next move."""
        return self._query("VA?")

    @speed_deg_s.setter
    def speed_deg_s(self, value: float) -> None:
        self._setting("VA", value)

    @property
    def accel_deg_s2(self) -> float:
        """AC?: acceleration."""
        return self._query("AC?")

    @accel_deg_s2.setter
    def accel_deg_s2(self, value: float) -> None:
        self._setting("AC", value)

    @property
    def decel_deg_s2(self) -> float:
        """AG?: deceleration."""
        return self._query("AG?")

    @decel_deg_s2.setter
    def decel_deg_s2(self, value: float) -> None:
        self._setting("AG", value)

    @property
    def limits_deg(self) -> tuple[float, float]:
        """(SL?, SR?): software travel limits."""
        return self._query("SL?"), self._query("SR?")

    @limits_deg.setter
    def limits_deg(self, value: tuple[float, float]) -> None:
        lo, hi = float(value[0]), float(value[1])
        if not lo < hi:
            raise ValueError(f"{self.name}: limits must be (lo, hi) with lo < hi, got {value!r}")
        cur_lo, _ = self.limits_deg
        # order the two commands so the pair stays valid (SL < SR) in between
        for cmd, v in ((("SR", hi), ("SL", lo)) if lo >= cur_lo else (("SL", lo), ("SR", hi))):
            self._setting(cmd, v)
