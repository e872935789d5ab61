"""A VISA resource as a byte link (drivers.byte_link), through PyVISA: USB-TMC
(`USB0::0x1313::0x8072::P2000000::INSTR`), serial (`ASRL/dev/ttyUSB0::INSTR`) and raw TCP
(`TCPIP0::host::port::SOCKET`) alike, from the backend that GONIO_VISA_LIBRARY names
(pyvisa-py, "@py", by default; "@ivi" for NI-VISA or another IVI VISA).

Each read returns one line (the resource's termination character is the reply terminator's
last byte) and waits only as long as the transport's deadline leaves: the resource's timeout
is set to the time left (in whole ms, set again only when it changes). A VISA timeout is no
reply yet (b""); every other failure, whatever the backend raises (a VisaIOError, or pyserial's
and socket's own exceptions that pyvisa-py lets through), is a LinkFailure. A line that a
timeout cuts off is lost (PyVISA drops a timed-out read's bytes); its tail, when it comes,
is a late reply the transport tells apart.
"""

from __future__ import annotations

import math
import os
import termios
from typing import Any

from drivers.byte_link import LineSettings, LinkFailure

LIBRARY_ENV = "GONIO_VISA_LIBRARY"
DEFAULT_LIBRARY = "@py"  # pyvisa-py (with pyusb for USB-TMC)
VISA_MISSING = "PyVISA is not installed (pip install 'gonio[visa]')"
MESSAGE_BASED = ("INSTR", "SOCKET")  # the resource classes a line device is reached by


def visa_library() -> str:
    """The VISA backend links open resources with: GONIO_VISA_LIBRARY, else pyvisa-py."""
    return os.environ.get(LIBRARY_ENV, "").strip() or DEFAULT_LIBRARY


class VisaLink:
    """A VISA resource opened for line exchanges; line settings apply to an ASRL resource."""

    noun = "VISA resource"

    def __init__(self, resource: str, line: LineSettings, read_eol: bytes, timeout_s: float):
        self.endpoint = resource
        try:
            import pyvisa
            from pyvisa import constants, rname
        except ImportError as exc:
            raise LinkFailure(ImportError(VISA_MISSING)) from exc
        try:
            kind = rname.parse_resource_name(resource).resource_class
        except rname.InvalidResourceName as exc:
            raise LinkFailure(exc) from exc
        if kind not in MESSAGE_BASED:
            raise LinkFailure(ValueError(f"{kind} resources exchange no lines; give an "
                                         f"{' or '.join(MESSAGE_BASED)} resource"))
        self._constants, self._socket = constants, kind == "SOCKET"
        self._io_failures = (pyvisa.errors.Error, OSError, termios.error)
        self._write_ms = self._timeout_ms = max(1, math.ceil(timeout_s * 1000))
        self._res: Any = None
        self._closed = False
        try:
            # PyVISA keeps one ResourceManager per library, shared by the whole process
            self._res = pyvisa.ResourceManager(visa_library()).open_resource(
                resource, timeout=self._timeout_ms, read_termination=read_eol.decode("ascii"))
            self._asrl = self._res.interface_type == constants.InterfaceType.asrl
            if self._asrl:
                self._set_line(line)
        except Exception as exc:  # any backend's failure to open (pyvisa-py raises bare ones)
            self.close()
            raise LinkFailure(exc) from exc

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

    def discard_input(self) -> None:
        """An ASRL resource's receive buffer is flushed; a socket's bytes held past the last
        line are dropped (message-based resources, USB-TMC, hold none between requests)."""
        ops = self._constants.BufferOperation
        try:
            if self._asrl:
                self._res.flush(ops.discard_read_buffer | ops.discard_receive_buffer)
            elif self._socket:
                self._res.flush(ops.discard_read_buffer_no_io)
        except self._io_failures as exc:
            raise LinkFailure(exc) from exc

    def write(self, data: bytes) -> None:
        """write_raw within the transport's timeout."""
        try:
            self._timeout(self._write_ms)
            self._res.write_raw(data)
        except self._io_failures as exc:
            raise LinkFailure(exc, self._timed_out(exc)) from exc

    def read(self, wait_s: float) -> bytes:
        """One line (terminator included) if it comes within wait_s, else b""."""
        try:
            self._timeout(max(1, math.ceil(wait_s * 1000)))
            return self._res.read_raw()
        except self._io_failures as exc:
            if self._timed_out(exc):
                return b""
            raise LinkFailure(exc) from exc

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
