"""A VISA resource as a byte link (drivers.byte_link), through PyVISA: USB-TMC
(`USB0::0x1313::0x8072::P2000000::INSTR`), serial (`ASRL/dev/ttyUSB0::INSTR`) and raw TCP
(`TCPIP0::host::port::SOCKET`) alike, from the backend that GONIO_VISA_LIBRARY names
(pyvisa-py, "@py", by default; "@ivi" for NI-VISA or another IVI VISA).

An ASRL read returns what has arrived, as a serial port's does (drivers.serial_link): it waits
for a first byte in slices of the resource's timeout (READ_SLICE_S, the last one cut to the
deadline) and takes what else the buffer holds (`bytes_in_buffer`). pyvisa-py reads a serial
line one byte at a time, each with the whole timeout, so a line read whole could run a timeout
past its deadline; and each change of an ASRL resource's timeout makes pyserial set the port
again (tcsetattr), so the timeout stays at one slice but for a deadline's last one. A USB-TMC
or socket read returns one line (the resource's termination character is the reply
terminator's last byte) within the time left (the timeout, in whole ms, set when it changes);
a line that such a timeout cuts off is lost (PyVISA drops a timed-out read's bytes) and its
tail, when it comes, is a late reply the transport tells apart. A VISA timeout is no reply yet
(b""); every other failure, whatever the backend raises (a VisaIOError, or pyserial's and
socket's own exceptions that pyvisa-py lets through), is a LinkFailure, one that keeps a
resource from opening with what a lab can do about it (drivers.open_failure).
"""

from __future__ import annotations

import math
import os
import termios
import time
from typing import Any

from drivers.byte_link import LineSettings, LinkFailure
from drivers.open_failure import port_open_failure, usb_open_failure

LIBRARY_ENV = "GONIO_VISA_LIBRARY"
DEFAULT_LIBRARY = "@py"  # pyvisa-py (with pyusb for USB-TMC)
VISA_MISSING = "PyVISA is not installed (pip install 'gonio[visa]')"
MESSAGE_BASED = ("INSTR", "SOCKET")  # the resource classes a line device is reached by
#: VISA's resource classes (VPP-4.3), the last part of a resource string
RESOURCE_CLASSES = ("INSTR", "SOCKET", "INTFC", "BACKPLANE", "MEMACC", "SERVANT", "RAW")
READ_SLICE_S = 0.05  # an ASRL read waits for its first byte this long at a time


def visa_library() -> str:
    """The VISA backend links open resources with: GONIO_VISA_LIBRARY, else pyvisa-py."""
    return os.environ.get(LIBRARY_ENV, "").strip() or DEFAULT_LIBRARY


def visa_name(resource: str) -> str:
    """The resource string with its class in capitals: VISA resource names ignore case, and
    PyVISA's parser reads the class in capitals only (`tcpip::host::5025::socket`)."""
    head, sep, last = resource.strip().rpartition("::")
    return f"{head}{sep}{last.upper()}" if sep and last.upper() in RESOURCE_CLASSES \
        else resource.strip()


def line_resource(resource: str) -> Any:
    """The parsed name (pyvisa.rname's ResourceName: interface_type, resource_class, ...) of a
    resource a line device may be reached by. ImportError (VISA_MISSING) without PyVISA;
    ValueError for a string that is no VISA resource name, or one of a class that exchanges no
    lines (neither INSTR nor SOCKET)."""
    try:
        from pyvisa import rname
    except ImportError:
        raise ImportError(VISA_MISSING) from None
    try:
        parsed = rname.parse_resource_name(visa_name(resource))
    except rname.InvalidResourceName as exc:
        raise ValueError(str(exc)) from None
    if parsed.resource_class not in MESSAGE_BASED:
        raise ValueError(f"{parsed.resource_class} resources exchange no lines; give an "
                         f"{' or '.join(MESSAGE_BASED)} resource")
    if parsed.interface_type == "USB":
        _check_usb_numbers(parsed)
    return parsed


def _check_usb_numbers(parsed: Any) -> None:
    """A USB resource's vendor and product ids (hex or decimal) and interface number (decimal)
    are numbers: PyVISA parses `...::P2000000::INSTRR` as interface `INSTRR` of an INSTR
    resource, which would only fail later as a meter not found."""
    for field, text, base in (("vendor id", parsed.manufacturer_id, 0),
                              ("product id", parsed.model_code, 0),
                              ("interface number", parsed.usb_interface_number, 10)):
        try:
            int(text, base)
        except ValueError:
            raise ValueError(f"its USB {field} {text!r} is not a number (a USB resource is "
                             "USB<board>::<vendor id>::<product id>::<serial>"
                             "[::<interface>]::INSTR)") from None


def _ms(seconds: float) -> int:
    """A VISA timeout: whole milliseconds, at least one."""
    return max(1, math.ceil(seconds * 1000))


class VisaLink:
    """A VISA resource opened for line exchanges; line settings apply to an ASRL resource.
    A write waits timeout_s for the link to take it, on an ASRL resource one read slice (the
    port's buffer takes a line at once unless flow control has held it full that long)."""

    noun = "VISA resource"

    def __init__(self, resource: str, line: LineSettings, read_eol: bytes, timeout_s: float):
        self.endpoint = resource
        try:
            parsed = line_resource(resource)
            import pyvisa
            from pyvisa import constants
        except (ImportError, ValueError) as exc:
            raise LinkFailure(exc) from exc
        self._constants = constants
        self._asrl = parsed.interface_type == "ASRL"
        self._io_failures = (pyvisa.errors.Error, OSError, termios.error)
        # what writes wait and, on an ASRL resource, each read slice
        self._base_ms = self._timeout_ms = _ms(READ_SLICE_S if self._asrl else timeout_s)
        self._res: Any = None
        self._closed = False
        try:
            # PyVISA keeps one ResourceManager per library, shared by the whole process; an
            # exclusive lock keeps other sessions out where the library locks (NI-VISA's do:
            # a second one is VI_ERROR_RSRC_LOCKED; pyvisa-py ignores it, the hold guards)
            self._res = pyvisa.ResourceManager(visa_library()).open_resource(
                visa_name(resource), timeout=self._timeout_ms,
                read_termination=read_eol.decode("ascii"),
                access_mode=pyvisa.constants.AccessModes.exclusive_lock)
            if self._asrl:
                self._set_line(line)
        except Exception as exc:  # any backend's failure to open (pyvisa-py raises bare ones)
            self.close()
            raise LinkFailure(_open_failure(exc, parsed)) from exc

    def _set_line(self, line: LineSettings) -> None:
        """Baud rate, eight data bits, parity, stop bits and flow control of an ASRL resource."""
        c = self._constants
        res = self._res
        res.baud_rate, res.data_bits = line.baudrate, 8
        res.parity = getattr(c.Parity, line.parity)
        res.stop_bits = {1: c.StopBits.one, 1.5: c.StopBits.one_and_a_half,
                         2: c.StopBits.two}[line.stopbits]
        res.flow_control = ((c.VI_ASRL_FLOW_RTS_CTS if line.rtscts else 0)
                            | (c.VI_ASRL_FLOW_XON_XOFF if line.xonxoff else 0))

    def _timeout(self, ms: int) -> None:
        if ms != self._timeout_ms:
            self._res.timeout = ms
            self._timeout_ms = ms

    def take_input(self) -> bytes:
        """What an ASRL resource's receive buffer holds, read out without waiting; nothing
        from a socket or USB-TMC resource, whose library keeps what came after the last line
        and hands it over as lines (a line's head joined by its tail)."""
        taken = bytearray()
        try:
            while self._asrl and (chunk := self._arrived(time.monotonic())):
                taken += chunk
        except self._io_failures as exc:
            raise LinkFailure(exc) from exc
        return bytes(taken)

    def write(self, data: bytes) -> None:
        """write_raw within the transport's timeout."""
        try:
            self._timeout(self._base_ms)
            self._res.write_raw(data)
        except self._io_failures as exc:
            raise LinkFailure(exc, self._timed_out(exc)) from exc

    def read(self, wait_s: float) -> bytes:
        """What has arrived within wait_s (an ASRL resource), or one line (terminator
        included) if it comes within wait_s; b"" if nothing did."""
        try:
            if self._asrl:
                return self._arrived(time.monotonic() + wait_s)
            self._timeout(_ms(wait_s))
            return self._res.read_raw()
        except self._io_failures as exc:
            if self._timed_out(exc):
                return b""
            raise LinkFailure(exc) from exc

    def _arrived(self, deadline: float) -> bytes:
        """What the ASRL resource's buffer holds, once a first byte has come by the monotonic
        deadline (waited for a slice at a time, the last one cut to the deadline)."""
        res = self._res
        while not res.bytes_in_buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                return b""
            self._timeout(min(self._base_ms, _ms(left)))
            try:
                first = res.read_bytes(1)
            except self._io_failures as exc:
                if self._timed_out(exc):
                    continue
                raise
            waiting = res.bytes_in_buffer
            return first + res.read_bytes(waiting) if waiting else first
        return res.read_bytes(res.bytes_in_buffer)

    def _timed_out(self, exc: BaseException) -> bool:
        return getattr(exc, "error_code", None) == self._constants.StatusCode.error_timeout

    def close(self) -> None:
        """Close the resource (quiet: one whose device has gone closes without error)."""
        if self._res is not None and not self._closed:
            self._closed = True
            try:
                self._res.close()
            except Exception:  # closing in a `finally` must not hide the error that ended it
                pass


def _open_failure(exc: BaseException, parsed: Any) -> BaseException:
    """Why the resource did not open, with what a lab can do: a USB instrument may be absent
    or need a udev rule, a serial port the `dialout` group (drivers.open_failure)."""
    if parsed.interface_type == "USB":
        return usb_open_failure(exc, parsed.manufacturer_id)
    if parsed.interface_type == "ASRL":
        return port_open_failure(exc)
    return exc
