"""Line-oriented serial transport (pyserial) with bounded, named timeouts and safe retries.

Protocol drivers send a line and read a reply line through it. Only queries are retried
(after a timeout or a garbled reply); a command that changes the device's state is sent
exactly once and its outcome is re-read by the driver instead.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TypeVar

import serial

from drivers.base import DeviceTimeout, DriverError, ProtocolError

T = TypeVar("T")


class SerialLineTransport:
    """A serial port exchanging ASCII lines, thread-safe (one exchange at a time).

    write_eol / read_eol: the line terminators sent and expected; timeout_s: how long a
    reply may take; retries: extra attempts a query gets after a timeout or garbled reply.
    """

    def __init__(
        self,
        port: str,
        *,
        name: str,
        baudrate: int = 19200,
        write_eol: bytes = b"\r",
        read_eol: bytes = b"\r\n",
        timeout_s: float = 1.0,
        retries: int = 2,
        rtscts: bool = False,
    ):
        if not timeout_s > 0:
            raise ValueError(f"{name}: timeout_s must be > 0, got {timeout_s!r}")
        if retries < 0:
            raise ValueError(f"{name}: retries must be >= 0, got {retries!r}")
        self.name, self.port = name, port
        self.write_eol, self.read_eol = write_eol, read_eol
        self.timeout_s, self.retries = float(timeout_s), int(retries)
        self.lock = threading.RLock()
        try:
            self._serial = serial.serial_for_url(
                port, baudrate=baudrate, timeout=timeout_s, write_timeout=timeout_s,
                rtscts=rtscts,
            )
        except (serial.SerialException, ValueError) as exc:
            raise DriverError(f"{name}: cannot open serial port {port!r}: {exc}") from None
        self._serial.reset_input_buffer()

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Close the port (idempotent)."""
        self._serial.close()

    def __enter__(self) -> SerialLineTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- bytes ------------------------------------------------------------------
    def _lost(self, exc: Exception) -> DriverError:
        return DriverError(f"{self.name}: serial connection on {self.port!r} lost: {exc}")

    def send(self, line: str) -> None:
        """Discard stale input, then write one line (terminator added)."""
        data = line.encode("ascii") + self.write_eol
        with self.lock:
            try:
                self._serial.reset_input_buffer()
                self._serial.write(data)
                self._serial.flush()
            except (serial.SerialException, OSError) as exc:
                raise self._lost(exc) from None

    def read_line(self, what: str, timeout_s: float | None = None) -> str:
        """Read one reply line (terminator stripped).

        Reads whatever has arrived in one call rather than pyserial's byte-at-a-time
        read_until; bytes after the terminator are dropped (a line protocol sends one
        reply per request). Raises DeviceTimeout(what) when no complete line arrives in
        time, ProtocolError when it holds bytes that are not printable ASCII.
        """
        timeout = self.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        data = bytearray()
        with self.lock:
            try:
                while self.read_eol not in data:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise DeviceTimeout(self.name, what, timeout)
                    self._serial.timeout = left
                    chunk = self._serial.read(max(1, self._serial.in_waiting))
                    if not chunk:
                        raise DeviceTimeout(self.name, what, timeout)
                    data += chunk
            except (serial.SerialException, OSError) as exc:
                raise self._lost(exc) from None
        body = bytes(data[: data.index(self.read_eol)])
        if any(b < 0x20 or b > 0x7E for b in body):
            raise ProtocolError(f"{self.name}: garbled reply to {what}: {bytes(data)!r}")
        return body.decode("ascii")

    def exchange(self, line: str, what: str | None = None) -> str:
        """Send a line and read its reply once (no retry: for state-changing commands)."""
        with self.lock:
            self.send(line)
            return self.read_line(what or repr(line))

    def query(
        self,
        line: str,
        parse: Callable[[str], T],
        what: str | None = None,
    ) -> T:
        """Send a query and parse its reply, retrying after a timeout or garbled reply.

        parse raises ProtocolError for a reply it cannot read (retried) or DeviceError for
        a device error (not retried). After 1 + retries failed attempts the last
        DeviceTimeout / ProtocolError is raised.
        """
        what = what or repr(line)
        last: DriverError | None = None
        with self.lock:
            for _ in range(1 + self.retries):
                try:
                    return parse(self.exchange(line, what))
                except (DeviceTimeout, ProtocolError) as exc:
                    last = exc
        assert last is not None
        raise last
