"""Line-oriented serial transport (pyserial) with bounded, named timeouts and safe retries.

Protocol drivers send a line and read a reply line through it. Only queries are retried
(after a timeout or a garbled reply); a command that changes the device's state is sent
exactly once and its outcome is re-read by the driver instead. Every failure of the port
itself (pyserial's SerialException, OSError, and the termios.error a vanished pty or USB
adaptor raises) becomes a SerialPortError, so callers see only DriverError subclasses.

A reply that missed its timeout may still arrive, after the next query has been sent, and
would be read as that query's answer (a power reading taken at the previous stage position).
So after a timeout the transport is out of step: before its next exchange it sends the
driver's sync query, whose answer no other exchange produces, and discards every line up to
that answer (the device answers in order, so whatever was late has come out by then). A
garbled reply that arrives in step is the answer to the line just sent, garbled.
"""

from __future__ import annotations

import re
import select
import termios
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar

import serial

from drivers.base import DeviceTimeout, DriverError, ProtocolError

T = TypeVar("T")

# What pyserial lets through when a port fails: its own exception, OSError from os.read /
# os.write / ioctl, and termios.error (no OSError subclass) from tcflush / tcdrain / tcsetattr.
PORT_FAILURES = (serial.SerialException, OSError, termios.error)
PRINTABLE = bytes(range(0x20, 0x7F))


class SerialPortError(DriverError):
    """The serial port itself failed (could not be opened, or went away: unplugged USB
    adaptor, pty whose far side closed); `action` says what the driver was doing."""

    def __init__(self, device: str, port: str, action: str, cause: BaseException):
        self.device, self.port, self.action, self.cause = device, port, action, cause
        what = "could not be opened" if action == "opening" else f"went away ({action})"
        super().__init__(f"{device}: serial port {port} {what}: {_describe(cause)}")


def _describe(exc: BaseException) -> str:
    """termios.error carries (errno, text) as a tuple; show it as OSError does."""
    if isinstance(exc, termios.error) and len(exc.args) == 2:
        return f"[Errno {exc.args[0]}] {exc.args[1]}"
    return str(exc) or type(exc).__name__


def strict_number_parser(pattern: str, expected: str) -> Callable[[str], float]:
    """A reader of numeric replies that must match pattern exactly: ASCII replies carry no
    checksum, so a dropped or garbled byte must break the shape (ProtocolError naming the
    expected form) rather than pass as another number."""
    shape = re.compile(pattern)

    def parse(text: str) -> float:
        if shape.fullmatch(text) is None:
            raise ProtocolError(f"garbled number {text!r} (expected {expected})")
        return float(text)

    return parse


@dataclass(frozen=True)
class SyncQuery:
    """A query whose reply no other exchange of the driver produces (`is_reply` tells it),
    sent to bring replies back in step after a timeout."""

    line: str
    is_reply: Callable[[str], bool]


class SerialLineTransport:
    """A serial port exchanging ASCII lines, thread-safe (one exchange at a time).

    write_eol / read_eol: the line terminators sent and expected; timeout_s: how long a
    reply may take; retries: extra attempts a query gets after a timeout or garbled reply;
    sync: the driver's SyncQuery (None: input is only flushed before each write, which
    catches a late reply only if it has already arrived).
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
        sync: SyncQuery | None = None,
    ):
        if not timeout_s > 0:
            raise ValueError(f"{name}: timeout_s must be > 0, got {timeout_s!r}")
        if retries < 0:
            raise ValueError(f"{name}: retries must be >= 0, got {retries!r}")
        self.name, self.port = name, port
        self.write_eol, self.read_eol = write_eol, read_eol
        self.timeout_s, self.retries = float(timeout_s), int(retries)
        self.sync = sync
        self.in_step = True  # False after a timeout, until a sync succeeds
        self.resyncs = 0  # sync queries answered (how often replies were out of step)
        self._syncs_unanswered = 0  # sync queries whose reply has not been read yet
        self._rx = bytearray()  # bytes read past the last reply line
        self.lock = threading.RLock()
        try:
            self._serial = serial.serial_for_url(
                port, baudrate=baudrate, timeout=timeout_s, write_timeout=timeout_s,
                rtscts=rtscts,
            )
        except (*PORT_FAILURES, ValueError) as exc:
            raise SerialPortError(name, port, "opening", exc) from exc
        try:
            with self._port("discarding stale input"):
                self._serial.reset_input_buffer()
        except DriverError:
            self.close()
            raise

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Close the port (idempotent; a port that has already gone away closes quietly,
        so closing in a `finally` never hides the error that ended the session)."""
        try:
            self._serial.close()
        except PORT_FAILURES:
            pass

    def __enter__(self) -> SerialLineTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- bytes ------------------------------------------------------------------
    @contextmanager
    def _port(self, action: str) -> Iterator[None]:
        """Turn a port failure during `action` into SerialPortError (a blocked write into
        DeviceTimeout); DriverErrors raised inside pass through unchanged."""
        try:
            yield
        except serial.SerialTimeoutException:
            self.in_step = False  # part of a line may have gone out
            raise DeviceTimeout(self.name, f"the port to take {action}", self.timeout_s) from None
        except PORT_FAILURES as exc:
            raise SerialPortError(self.name, self.port, action, exc) from exc

    def send(self, line: str, what: str | None = None) -> None:
        """Bring replies back in step if a reply was missed (DeviceTimeout naming `what`
        if that fails), discard stale input, then write one line (terminator added)."""
        with self.lock:
            if not self.in_step and self.sync is not None:
                self._resync(what or repr(line))
            self._write(line)

    def _write(self, line: str) -> None:
        data = line.encode("ascii") + self.write_eol
        with self._port("discarding stale input"):
            self._serial.reset_input_buffer()
        self._rx.clear()
        with self._port(f"writing {line[:40]!r}{'...' if len(line) > 40 else ''}"):
            self._serial.write(data)
            self._serial.flush()

    def _resync(self, what: str) -> None:
        """Send the sync query and drop every line before a sync reply (late replies, garbled
        or not); DeviceTimeout, still out of step, if none comes in time. Nothing but sync
        queries is sent while out of step, so any sync reply means every earlier request
        has been answered; the surplus replies of sync queries that timed out are skipped
        when they turn up later (see _reply)."""
        assert self.sync is not None
        self._write(self.sync.line)
        self._syncs_unanswered += 1
        deadline = time.monotonic() + self.timeout_s
        while True:
            try:
                line = self._read_line(f"{what} (replies out of step after a timeout: "
                                       f"no answer to the sync query {self.sync.line!r})",
                                       deadline)
            except ProtocolError:
                continue
            if self.sync.is_reply(line):
                self._syncs_unanswered -= 1
                self.in_step = True
                self.resyncs += 1
                return

    def _reply(self, what: str) -> str:
        """The reply to the line just sent: the next line, past any late sync replies."""
        deadline = time.monotonic() + self.timeout_s
        while True:
            line = self._read_line(what, deadline)
            if not (self._syncs_unanswered and self.sync and self.sync.is_reply(line)):
                return line
            self._syncs_unanswered -= 1

    def _read_line(self, what: str, deadline: float) -> str:
        """Read one reply line (terminator stripped) by the monotonic `deadline`.

        Waits on the port's descriptor (select, up to the deadline) and reads whatever has
        arrived in one call, rather than pyserial's byte-at-a-time read_until or re-setting
        pyserial's timeout per read (each set re-applies the port's termios settings: two
        system calls per chunk); bytes after the terminator are kept for the next line (and
        discarded by the next send: a line protocol sends one reply per request). Raises
        DeviceTimeout(what) when no complete line arrives in time (the transport is then
        out of step: the reply may still come), ProtocolError when it holds bytes that are
        not printable ASCII.
        """
        data = self._rx
        with self.lock, self._port(f"reading the reply to {what}"):
            while self.read_eol not in data:
                left = deadline - time.monotonic()
                if left <= 0 or not select.select([self._serial.fileno()], [], [], left)[0]:
                    self.in_step = False
                    raise DeviceTimeout(self.name, what, self.timeout_s)
                data += self._serial.read(max(1, self._serial.in_waiting))
        end = data.index(self.read_eol)
        body = bytes(data[:end])
        del data[: end + len(self.read_eol)]
        if body.translate(None, PRINTABLE):  # any byte left is not printable ASCII
            raise ProtocolError(f"{self.name}: garbled reply to {what}: "
                                f"{body + self.read_eol!r}")
        return body.decode("ascii")

    def exchange(self, line: str, what: str | None = None) -> str:
        """Send a line and read its reply once (no retry: for state-changing commands)."""
        what = what or repr(line)
        with self.lock:
            self.send(line, what)
            return self._reply(what)

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
