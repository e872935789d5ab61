"""pymodbus 3.16's sync RTU client with its reply path made event-driven (request/reply latency).

pymodbus's serial client polls the port every millisecond and takes a reply only once its
byte count has stopped growing between two polls: about 2 ms per reply whatever the baud rate
(on a pty or a USB adapter most of a two-register read's round trip). `RtuClient` instead
blocks on the port until bytes arrive and hands them to pymodbus's RTU framer at once; the
framer ends a reply as soon as it is complete by its function code's length (and its CRC
checks), as a master on a real line does. A reply that stays short (a dropped byte) is still
a timeout at the link's reply_s, as before. (pymodbus's TCP client already waits on the
socket, so TCP needs no such change.)
"""

from __future__ import annotations

import time

import serial
from pymodbus.client import ModbusSerialClient
from pymodbus.exceptions import ConnectionException

from drivers.serial_link import write_through


class RtuClient(ModbusSerialClient):
    """Modbus RTU sync client whose reply reads wake on the port's bytes, never on a poll
    timer; every wait of one request is bounded by the client's timeout together."""

    _deadline = 0.0
    _waited = False  # a wait of the current reply has ended: later waits get what is left

    def send(self, request: bytes, addr: tuple | None = None) -> int:
        """Send a request frame and start its reply deadline; the frame is written through the
        port's descriptor (drivers.serial_link.write_through), since pyserial's write fails a
        write that all went out when the writer was descheduled longer than its timeout."""
        port, timeout_s = self.socket, self.comm_params.timeout_connect
        if port is not None and port.timeout != timeout_s:
            port.timeout = timeout_s  # shortened while the last reply came in pieces
        self._deadline, self._waited = time.monotonic() + timeout_s, False
        if port is None:
            raise ConnectionException(str(self))
        try:
            if waiting := port.in_waiting:  # as pymodbus: no stale byte before a request
                port.read(waiting)
            write_through(port, request)
        except serial.SerialTimeoutException:  # the port took no byte in the timeout
            raise ConnectionException(str(self)) from None
        except OSError:  # pyserial's SerialException: the port went away
            self.close()
            raise ConnectionException(str(self)) from None
        return len(request)

    def recv(self, size: int | None) -> bytes:
        """The bytes waiting now, or the first to arrive before the deadline and those with
        them; b"" at the deadline (pymodbus then reports no reply)."""
        port = self.socket
        if port is None:
            raise ConnectionException(str(self))
        try:
            if waiting := port.in_waiting:
                return port.read(waiting)
            left = self._deadline - time.monotonic()
            if left <= 0.0:
                return b""
            if self._waited:  # a later piece of the same reply: only the time left
                port.timeout = left
            self._waited = True
            first = port.read(1)
            return first + port.read(port.in_waiting) if first else b""
        except OSError:  # pyserial's SerialException: the port went away
            self.close()
            raise ConnectionException(str(self)) from None

