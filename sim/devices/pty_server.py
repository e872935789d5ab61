"""Serve an emulated serial device on a real pseudo-terminal (os.openpty).

The slave side (`.endpoint`, e.g. /dev/pts/7) is what pyserial, socat or a terminal
program opens. A thread reads the master side, cuts the byte stream into requests
(lines ending in a terminator, or frames ended by a silent gap for binary protocols
such as Modbus RTU), hands each to a handler and writes the reply through the fault
injector.
"""

from __future__ import annotations

import fcntl
import logging
import os
import select
import sys
import termios
import threading
import time
import tty
from collections.abc import Callable

from sim.devices.faults import FaultInjector

#: How long bytes written to the pty may take to show up in the host's input queue (the kernel
#: moves them asynchronously; tens of ms on a loaded machine): a hangup before they were ever
#: seen queued waits this long, so a host that read them at once is told apart from one whose
#: bytes are still on their way.
ARRIVAL_GRACE_S = 0.5

log = logging.getLogger(__name__)

Handler = Callable[[bytes], bytes | None]


class PtyServer:
    """A threaded pty server: bytes in, handler, reply bytes (with faults) out.

    handler(request) -> reply bytes (b"" or None = no reply). Line mode (terminators
    given): each request is one line without its terminator; bytes of `ignore` (e.g. a
    LF after a CR) are dropped. Frame mode (terminators=None): a request is whatever
    arrived before `frame_gap_s` of silence. A line longer than max_line is discarded up
    to its terminator and `on_overflow()` answers it instead. reply_tail / crc_bytes tell
    the fault injector which trailing reply bytes are a terminator or a CRC.
    """

    def __init__(
        self,
        handler: Handler,
        *,
        terminators: bytes | None = b"\r",
        ignore: bytes = b"",
        max_line: int = 1024,
        on_overflow: Callable[[], bytes | None] | None = None,
        frame_gap_s: float = 0.005,
        faults: FaultInjector | None = None,
        reply_tail: int = 0,
        crc_bytes: int = 0,
        name: str = "pty",
    ):
        self.handler = handler
        self.terminators = terminators
        self.ignore = ignore
        self.max_line = max_line
        self.on_overflow = on_overflow
        self.frame_gap_s = frame_gap_s
        self.faults = faults or FaultInjector()
        self.reply_tail, self.crc_bytes = reply_tail, crc_bytes
        self.name = name
        self.endpoint: str | None = None
        self.disconnected = False
        self.handler_errors: list[BaseException] = []
        self.requests = 0
        self._master = self._slave = -1
        self._wake_r = self._wake_w = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- lifecycle --------------------------------------------------------------
    def start(self) -> str:
        """Open the pty, start serving; returns the endpoint (slave device path)."""
        if self._thread is not None:
            raise RuntimeError(f"{self.name}: server already started")
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self._wake_r, self._wake_w = os.pipe()
        self.endpoint = os.ttyname(self._slave)
        self._thread = threading.Thread(target=self._serve, name=f"pty-{self.name}", daemon=True)
        self._thread.start()
        return self.endpoint

    def stop(self) -> None:
        """Stop serving and close the pty (idempotent)."""
        self._stop.set()
        if self._wake_w >= 0:
            try:
                os.write(self._wake_w, b"x")
            except OSError:
                pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._close_pty()
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                os.close(fd)
        self._wake_r = self._wake_w = -1

    def __enter__(self) -> PtyServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _close_pty(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1

    # -- serving ----------------------------------------------------------------
    def _serve(self) -> None:
        buf = bytearray()
        discarding = False
        while not self._stop.is_set() and not self.disconnected:
            timeout = self.frame_gap_s if (self.terminators is None and buf) else 0.5
            try:
                ready, _, _ = select.select([self._master, self._wake_r], [], [], timeout)
            except (OSError, ValueError):
                return
            if self._wake_r in ready:
                return
            if not ready:
                if self.terminators is None and buf:
                    request, buf = bytes(buf), bytearray()
                    self._dispatch(request)
                continue
            try:
                chunk = os.read(self._master, 4096)
            except BlockingIOError:
                continue
            except OSError:
                return
            if self.terminators is None:
                buf += chunk
                continue
            for byte in chunk:
                if byte in self.ignore:
                    continue
                if byte in self.terminators:
                    if not discarding:
                        request = bytes(buf)
                        self._dispatch(request)
                    buf.clear()
                    discarding = False
                    if self.disconnected:
                        return
                elif not discarding:
                    buf.append(byte)
                    if len(buf) > self.max_line:
                        buf.clear()
                        discarding = True
                        self._send(self._call(self.on_overflow) if self.on_overflow else None)

    def _dispatch(self, request: bytes) -> None:
        self.requests += 1
        self._send(self._call(self.handler, request))

    def _call(self, fn: Callable[..., bytes | None], *args: bytes) -> bytes | None:
        """Run the device logic; an exception is recorded and answered with silence."""
        try:
            return fn(*args)
        except Exception as exc:  # the device must survive its own bugs; tests check the list
            log.exception("%s: handler failed on %r", self.name, args)
            self.handler_errors.append(exc)
            return None

    def _send(self, reply: bytes | None) -> None:
        if not reply:
            return
        delay = self.faults.delay()
        if delay > 0.0 and self._stop.wait(delay):
            return
        out = self.faults.reply(reply, keep_tail=self.reply_tail, crc_bytes=self.crc_bytes)
        if out:
            self._write(out)
        if self.faults.should_disconnect():
            self._drain()
            self.disconnected = True
            self._close_pty()

    def _drain(self, timeout_s: float = 1.0) -> None:
        """Wait until the host has read what was sent (a hangup would flush it).

        The pty moves written bytes to the slave's input queue asynchronously, so first
        wait (briefly) for them to show up there, then for the queue to empty.
        """
        deadline = time.monotonic() + timeout_s
        arrived_by = time.monotonic() + ARRIVAL_GRACE_S
        seen = False
        while time.monotonic() < deadline and not self._stop.is_set():
            pending = fcntl.ioctl(self._slave, termios.TIOCINQ, b"\0\0\0\0")
            if int.from_bytes(pending, sys.byteorder) > 0:
                seen = True
            elif seen or time.monotonic() > arrived_by:
                return
            time.sleep(0.001)

    def _write(self, data: bytes) -> None:
        """Write everything, or drop what a full, unread pty cannot take (like a bare wire)."""
        view = memoryview(data)
        deadline = time.monotonic() + 1.0
        while view and time.monotonic() < deadline:
            try:
                n = os.write(self._master, view)
                view = view[n:]
            except BlockingIOError:
                time.sleep(0.001)
            except OSError:
                return


class PtyDevice:
    """Lifecycle shared by the line-oriented emulators: serve on a pty, stop, context manager.

    Subclasses set `self._server` (a PtyServer) and may extend `stop()`.
    """

    _server: PtyServer

    @property
    def endpoint(self) -> str | None:
        """The pty path hosts open (None before start)."""
        return self._server.endpoint

    @property
    def server(self) -> PtyServer:
        """The pty server (its handler_errors must stay empty)."""
        return self._server

    def start(self) -> str:
        """Serve on a new pty; returns its path."""
        return self._server.start()

    def stop(self) -> None:
        """Stop serving and close the pty."""
        self._server.stop()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
