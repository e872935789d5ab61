"""Driver for the Newport (Oriel) Cornerstone 130 / 260 monochromator (RS-232, 9600 baud 8N1).

From the Cornerstone manuals (MCS260 appendix I; 130B / 260B 15.3-15.9): statements end with a
line feed (we send CR LF, as the 130B's examples do), responses with CR LF. Over RS-232 every
statement is echoed as received before anything else, and a query's answer follows its echo;
a command has no answer. The transport reads and checks each echo (drivers.serial_transport,
`echo`): a command whose echo came back whole reached the device. Errors are not answered:
the device keeps the latest error code, which `ERROR?` answers and resets (1 not understood, 2
bad parameter, 3 wavelength not allowed, 6 accessory not present, 8 wavelength drive not homed,
9 label too long, 10 system error).

A state-changing command (GOWAVE, GRAT, SHUTTER, UNITS) is sent once (drivers.lost_reply) and
followed by `ERROR?`; the device handles statements in order, so that answer comes once the
command is done (a move's end). When the error code's reply is lost or garbled it cannot be
asked again (the first ask reset it): the device's state read back (WAVE?, GRAT?, SHUTTER?,
UNITS?) settles whether the command was taken. Queries are retried after a timeout or a
garbled reply; numeric answers must have the device's shape (digits, a point and up to three
decimals), and since a dropped digit keeps that shape (632.8 read as 62.8), a wavelength is
taken once two reads in a row agree (drivers.agreed_read). After a timeout INFO? (whose
answer, the model and firmware, no other query has) brings late replies back in step.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Unpack

from drivers.agreed_read import agreed
from drivers.base import DeviceError, DriverError, ProtocolError
from drivers.byte_link import LinkOptions
from drivers.lost_reply import LOST, not_resent, sent_once
from drivers.serial_transport import SerialLineTransport, SyncQuery

ERRORS = {1: "command not understood", 2: "bad parameter used in command",
          3: "destination position for wavelength motion not allowed",
          6: "accessory not present (usually filter wheel)", 8: "could not home wavelength drive",
          9: "label too long", 10: "system error"}
_NUMBER = re.compile(r"\d+(\.\d{1,3})?")
_CODE = re.compile(r"\d{1,3}")
_GRATING = re.compile(r"(\d),(\d+(?:\.\d{1,3})?),(.*)")
WAVELENGTH_UNIT_NM = 0.001  # the answers' last place: a read-back within it is the target


def wavelength(text: str) -> float:
    """A WAVE? answer (ProtocolError for any other shape than digits[.ddd])."""
    if _NUMBER.fullmatch(text) is None:
        raise ProtocolError(f"garbled wavelength {text!r}")
    return float(text)


def code_of(text: str) -> int:
    """An ERROR? answer."""
    if _CODE.fullmatch(text) is None:
        raise ProtocolError(f"garbled error code {text!r}")
    return int(text)


def grating(text: str) -> tuple[int, float, str]:
    """A GRAT? answer: (number, lines per mm, label)."""
    match = _GRATING.fullmatch(text)
    if match is None:
        raise ProtocolError(f"garbled grating {text!r}")
    return int(match.group(1)), float(match.group(2)), match.group(3)


def shutter(text: str) -> bool:
    """A SHUTTER? answer: True when open."""
    if text not in ("O", "C"):
        raise ProtocolError(f"garbled shutter state {text!r}")
    return text == "O"


class CornerstoneMonochromator:
    """A Cornerstone 130 or 260 on a serial port (or a VISA resource: LinkOptions) as a
    WavelengthSelector, in nm.

    grating: the grating to use (set when it opens; None leaves the one in place).
    """

    def __init__(self, port: str | None = None, *, grating: int | None = None,
                 name: str = "cornerstone", baudrate: int = 9600, timeout_s: float = 1.0,
                 retries: int = 2, **link: Unpack[LinkOptions]):
        self.name = name
        self.info: str | None = None
        self._target_nm: float | None = None
        self.transport = SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\r\n", read_eol=b"\r\n",
            echo=True, timeout_s=timeout_s, retries=retries,
            sync=SyncQuery("INFO?", self._is_info), **link)
        try:
            self.info = self.query("INFO?", str)
            self.query("ERROR?", code_of)  # start from no error
            self.command("UNITS NM", lambda: self.query("UNITS?", str) == "NM")
            if grating is not None:
                self.select_grating(grating)
        except BaseException:
            self.close()
            raise

    def _is_info(self, reply: str) -> bool:
        """The answer to INFO? (the sync query): once known, exactly it (before, while INFO?
        is first asked, whatever answers it)."""
        return self.info is None or reply == self.info

    # -- exchanges --------------------------------------------------------------
    def query(self, request: str, read: Callable[[str], object] = wavelength):
        """Ask a query, retried after a timeout or a garbled reply; its answer read by
        `read` (a ProtocolError from it is a garbled reply, asked again)."""
        def parse(reply: str) -> object:
            try:
                return read(reply)
            except ProtocolError as exc:
                raise ProtocolError(f"{self.name}: reply to {request!r}: {exc}") from None
        return self.transport.query(request, parse)

    def send(self, statement: str) -> None:
        """Send a command once, its echo read back (a lost echo: DeviceTimeout or
        ProtocolError; the command may have been taken, and is never re-sent)."""
        self.transport.send(statement)

    def error_code(self) -> int:
        """ERROR?, asked once (it resets the code): the latest error code, 0 for none."""
        try:
            return code_of(self.transport.exchange("ERROR?"))
        except ProtocolError as exc:
            raise ProtocolError(f"{self.name}: reply to 'ERROR?': {exc}") from None

    def _raise_for(self, code: int | None) -> None:
        if code:
            raise DeviceError(self.name, code, ERRORS.get(code, "error"))

    def command(self, statement: str, taken: Callable[[], bool]) -> None:
        """Send a command once, then its error code (DeviceError if not 0); when the echo or
        the code is lost, taken() reads the state back (DriverError: not confirmed)."""
        def sent() -> int:
            self.send(statement)
            return self.error_code()

        self._raise_for(sent_once(sent, taken, not_resent(self.name, statement)))

    # -- the monochromator ------------------------------------------------------
    def select_grating(self, number: int) -> None:
        """GRAT n: turn to grating n (returns when the change is done)."""
        self.command(f"GRAT {int(number)}", lambda: self.grating()[0] == int(number))

    def grating(self) -> tuple[int, float, str]:
        """GRAT?: the grating in use, its lines per mm and its label."""
        return self.query("GRAT?", grating)

    def open_shutter(self, is_open: bool) -> None:
        """SHUTTER O / SHUTTER C."""
        self.command(f"SHUTTER {'O' if is_open else 'C'}", lambda: self.shutter_open() is is_open)

    def shutter_open(self) -> bool:
        """SHUTTER?: True when the shutter is open."""
        return self.query("SHUTTER?", shutter)

    # -- WavelengthSelector -----------------------------------------------------
    def move_to_nm(self, wavelength_nm: float) -> None:
        """GOWAVE: start the drive toward wavelength_nm (returns at once; wait() settles it,
        a lost echo too: the move is never sent twice)."""
        if not wavelength_nm > 0:
            raise ValueError(f"{self.name}: wavelength must be > 0 nm, got {wavelength_nm!r}")
        self._target_nm = round(wavelength_nm, 3)
        try:
            self.send(f"GOWAVE {self._target_nm:.3f}")
        except LOST:
            pass

    def wait(self, timeout_s: float) -> float:
        """Until the drive is done with the last move_to_nm (its error code answers then:
        DeviceError 3 for a wavelength the grating cannot reach); the wavelength it reports,
        which must be the one asked for (DriverError: the move was not taken)."""
        target, self._target_nm = self._target_nm, None
        if target is None:
            return self.wavelength_nm()
        statement = f"GOWAVE {target:.3f}"
        try:
            with self.transport.longer_replies(timeout_s):
                self._raise_for(self.error_code())
        except LOST:
            pass  # the code is gone with its reply: the drive read back settles the move
        reached = self.wavelength_nm()
        if abs(reached - target) > WAVELENGTH_UNIT_NM / 2:
            raise DriverError(f"{self.name}: {statement!r} not taken: the drive is at "
                              f"{reached:g} nm; not re-sent")
        return reached

    def wavelength_nm(self) -> float:
        """WAVE?: the wavelength the drive is at, nm (two reads in a row that agree)."""
        return agreed(lambda: self.query("WAVE?"), self.name, "WAVE?",
                      reads=2 + self.transport.retries)

    def identity(self) -> dict[str, str]:
        """The monochromator's INFO? answer (model and firmware)."""
        return {"info": self.info or ""}

    def line_counts(self) -> dict[str, int]:
        """What the line has seen (drivers.base.LineCounts)."""
        return self.transport.line_counts()

    def close(self) -> None:
        """Close the port."""
        self.transport.close()
