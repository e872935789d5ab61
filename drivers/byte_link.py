"""The byte link under the line transport: one connection that moves a device's bytes (a serial
port through pyserial, drivers.serial_link, or a VISA resource through PyVISA,
drivers.visa_link), with the line settings an RS-232 adaptor needs.

drivers.serial_transport runs its line logic (reply sync, retries, garble checks, deadlines)
over either. A link reports every failure of its own as one LinkFailure carrying the library's
exception, which the transport names. drivers.open_link is the one place a link is opened.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol, TypedDict

PARITIES = ("none", "even", "odd", "mark", "space")
STOPBITS = (1, 1.5, 2)


@dataclass(frozen=True)
class LineSettings:
    """How an RS-232 line is set, on a serial port or a VISA ASRL resource: baud rate, parity
    (PARITIES), stop bits (STOPBITS), RTS/CTS and XON/XOFF flow control; eight data bits.
    A bad value is a ValueError naming the setting."""

    baudrate: int = 19200
    parity: str = "none"
    stopbits: float = 1
    rtscts: bool = False
    xonxoff: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.baudrate, bool) or not isinstance(self.baudrate, int) \
                or self.baudrate < 1:
            raise ValueError(f"baudrate must be a whole number of baud >= 1, got "
                             f"{self.baudrate!r}")
        if self.parity not in PARITIES:
            raise ValueError(f"parity must be one of {', '.join(PARITIES)}; got {self.parity!r}")
        if isinstance(self.stopbits, bool) or self.stopbits not in STOPBITS:
            raise ValueError(f"stopbits must be one of 1, 1.5, 2; got {self.stopbits!r}")
        for flag in ("rtscts", "xonxoff"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"{flag} must be true or false, got {getattr(self, flag)!r}")


def on_the_line(line: LineSettings, path: Path | None) -> LineSettings:
    """The settings a port can take: a pseudo-terminal (an emulator's, or socat's bridge to a
    network serial server) carries no parity bit, and Linux refuses a tcsetattr that asks for
    one and changes nothing else (EINVAL), so a pty gets no parity; a real port, all of them."""
    try:
        pty = path is not None and is_pty(os.stat(path))
    except OSError:  # the open that follows names what is wrong with the port
        pty = False
    return replace(line, parity="none") if pty else line


# Unix 98 pty slaves (/dev/pts/N): the kernel's device majors for them
PTY_MAJORS = range(136, 144)


def is_pty(status: os.stat_result) -> bool:
    """True for the status (os.stat / os.fstat) of a pseudo-terminal's slave side."""
    return os.major(status.st_rdev) in PTY_MAJORS


class LinkOptions(TypedDict, total=False):
    """What a line driver passes on to its transport about the link besides its port and baud
    rate: a VISA resource instead of the port, and the other line settings."""

    resource: str
    parity: str
    stopbits: float
    rtscts: bool
    xonxoff: bool


class LinkFailure(Exception):
    """The link itself failed: it could not be opened, it went away, or a write did not go
    out in time (write_timed_out). cause: the library's own exception."""

    def __init__(self, cause: BaseException, write_timed_out: bool = False):
        self.cause, self.write_timed_out = cause, write_timed_out
        super().__init__(str(cause))


class ByteLink(Protocol):
    """A connection moving a device's bytes. endpoint: the port or resource as errors name it;
    noun: what it is ("serial port", "VISA resource"). Every method raises LinkFailure."""

    endpoint: str
    noun: str

    def take_input(self) -> bytes:
        """The input that has arrived and not been read, taken without waiting (the
        transport sorts it: whole lines are stale, a part line's tail is still to come)."""

    def write(self, data: bytes) -> None:
        """Send all of data (LinkFailure with write_timed_out if it does not go in time)."""

    def read(self, wait_s: float) -> bytes:
        """What arrives within wait_s seconds (b"" if nothing did)."""

    def close(self) -> None:
        """Close the link (quiet and idempotent: a link already gone closes without error)."""

