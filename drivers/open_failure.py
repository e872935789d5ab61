"""Why a serial port or a VISA resource could not be opened, as one clause with what a lab can
do about it: the system's reason once (pyserial's own text names the path twice and the error
number twice), the `dialout` group for a port this user may not open, a udev rule for a USB
instrument that cannot be found. The library's exception stays the clause's __cause__.
"""

from __future__ import annotations

import errno
import os

#: Where a lab reads how to give a user its instruments (the udev rule for a USB instrument).
SETUP_DOC = "docs/real-bench.md"


class OpenFailure(OSError):
    """A link's failure to open as it is reported: the system's error number where there is
    one, and one clause."""


def _caused_by(failure: OpenFailure, cause: BaseException) -> OpenFailure:
    failure.__cause__ = cause
    return failure


def port_open_failure(exc: BaseException) -> BaseException:
    """The failure to open a serial port (pyserial's exception, or an OSError) as
    `[Errno N] reason`, a port this user may not open naming the `dialout` group; a failure
    with no error number (a setting the port refuses) as it is."""
    code = getattr(exc, "errno", None)
    if not isinstance(code, int):
        return exc
    reason = os.strerror(code)
    if code in (errno.EACCES, errno.EPERM):
        reason += (": this user needs the `dialout` group (sudo usermod -aG dialout USER, then "
                   "log in again) or a udev rule giving it the port")
    return _caused_by(OpenFailure(code, reason), exc)


def usb_open_failure(exc: BaseException, vendor: str) -> OpenFailure:
    """The failure to open a USB instrument (pyvisa-py's "No device found.", a USB error, a
    VISA status) with why that may be: it is absent, or this user may not reach it without a
    udev rule for its vendor id (`vendor`, e.g. 0x1313)."""
    reason = (str(exc) or type(exc).__name__).rstrip(".")
    return _caused_by(OpenFailure(
        f"{reason}: the instrument may be absent (not plugged in, switched off) or not "
        f"accessible to this user (a udev rule for USB vendor {vendor} gives access; "
        f"{SETUP_DOC})"), exc)
