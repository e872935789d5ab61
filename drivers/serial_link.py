"""A serial port as a byte link (drivers.byte_link), through pyserial: its descriptor is
waited on with select and read in one os.read per wake-up, rather than pyserial's
byte-at-a-time reads or a per-read timeout (each set re-applies the port's termios
settings: two system calls per chunk).

Every failure of the port (pyserial's SerialException, OSError, and the termios.error a
vanished pty or USB adaptor raises) becomes a LinkFailure carrying it; one that keeps the port
from opening carries it as one clause with what a lab can do about it (drivers.open_failure).
"""

from __future__ import annotations

import os
import select
import termios

import serial

from drivers.byte_link import LineSettings, LinkFailure
from drivers.open_failure import port_open_failure

# What pyserial lets through when a port fails: its own exception, OSError from os.read /
# os.write / ioctl, and termios.error (no OSError subclass) from tcdrain / tcsetattr.
PORT_FAILURES = (serial.SerialException, OSError, termios.error)
PARITY = {"none": serial.PARITY_NONE, "even": serial.PARITY_EVEN, "odd": serial.PARITY_ODD,
          "mark": serial.PARITY_MARK, "space": serial.PARITY_SPACE}
STOPBITS = {1: serial.STOPBITS_ONE, 1.5: serial.STOPBITS_ONE_POINT_FIVE, 2: serial.STOPBITS_TWO}


def write_through(port: serial.Serial, data: bytes) -> None:
    """One os.write on the port's descriptor (pyserial opens it non-blocking); pyserial's
    write, which waits for room up to the write timeout, only for what the port did not take at
    once. (pyserial's write selects for room after every write and fails with a write timeout
    when that write took longer than the timeout, so a stall of the writer under load would
    read as a port that takes no bytes.)"""
    try:
        written = os.write(port.fileno(), data)
    except BlockingIOError:
        written = 0
    if written < len(data):
        port.write(data[written:])


class SerialLink:
    """A serial port opened with the line settings; timeout_s bounds a write."""

    noun = "serial port"

    def __init__(self, port: str, line: LineSettings, timeout_s: float):
        self.endpoint = port
        try:
            self._serial = serial.serial_for_url(
                port, baudrate=line.baudrate, parity=PARITY[line.parity],
                stopbits=STOPBITS[line.stopbits], rtscts=line.rtscts, xonxoff=line.xonxoff,
                timeout=timeout_s, write_timeout=timeout_s,
            )
        except (*PORT_FAILURES, ValueError) as exc:
            raise LinkFailure(port_open_failure(exc)) from exc
        self.fd = self._serial.fileno()

    def take_input(self) -> bytes:
        """What the port's input queue holds, read out rather than flushed (tcflush would drop
        the head of a line whose tail is still to come)."""
        taken = bytearray()
        while chunk := self.read(0):
            taken += chunk
        return bytes(taken)

    def write(self, data: bytes) -> None:
        """Write data (write_through), then wait until it is transmitted."""
        try:
            write_through(self._serial, data)
            self._serial.flush()
        except PORT_FAILURES as exc:
            raise LinkFailure(exc, isinstance(exc, serial.SerialTimeoutException)) from exc

    def read(self, wait_s: float) -> bytes:
        """What has arrived within wait_s, in one os.read (b"" on a spurious wake-up)."""
        try:
            if not select.select([self.fd], [], [], wait_s)[0]:
                return b""
            try:
                chunk = os.read(self.fd, 4096)
            except BlockingIOError:
                return b""
            if not chunk:  # what pyserial's read raises for a readable port with nothing to read
                raise serial.SerialException("device reports readiness to read but returned no "
                                             "data (device disconnected or multiple access on "
                                             "port?)")
            return chunk
        except PORT_FAILURES as exc:
            raise LinkFailure(exc) from exc

    def close(self) -> None:
        """Close the port (a port that has already gone away closes quietly)."""
        try:
            self._serial.close()
        except PORT_FAILURES:
            pass
