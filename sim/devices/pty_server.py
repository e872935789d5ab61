"""Serve an emulated serial device on a real pseudo-terminal (os.openpty), or on raw TCP.

The slave side (`.endpoint`, e.g. /dev/pts/7) is what pyserial, socat, a terminal program or
a VISA library's ASRL resource (`ASRL/dev/pts/7::INSTR`) opens. Served on TCP instead
(`start_tcp`), the device listens on 127.0.0.1 (`.endpoint` is HOST:PORT) for one client at a
time, as an instrument's raw socket port does (a VISA `TCPIP0::127.0.0.1::PORT::SOCKET`). A
thread reads the pty's master side or the connection, cuts the byte stream into requests
(lines ending in a terminator, or frames ended by a silent gap for binary protocols such as
Modbus RTU), hands each to a handler and writes the reply through the fault injector.
"""

from __future__ import annotations

import fcntl
import logging
import os
import select
import socket
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
LOOPBACK = "127.0.0.1"
WRITE_GIVE_UP_S = 1.0  # a reply the host does not take within this is dropped, as on a wire

log = logging.getLogger(__name__)

Handler = Callable[[bytes], bytes | None]


class _Closed(Exception):
    """The channel is gone for good (the pty closed, the listener shut): serving ends."""


class PtyPair:
    """A raw pty pair: hosts open `path` (the slave); the server talks through the master
    (non-blocking). The pair keeps a slave fd of its own, so the pty lives on while hosts
    open and close it."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)

    def unread_by_host(self) -> int:
        """Bytes sent to the host that it has not read yet (the slave's input queue)."""
        return int.from_bytes(fcntl.ioctl(self.slave, termios.TIOCINQ, b"\0\0\0\0"),
                              sys.byteorder)

    def close(self) -> None:
        """Close both ends (idempotent): the host's reads fail and the path goes away."""
        for fd in (self.master, self.slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self.slave = -1


class _PtyChannel(PtyPair):
    """A pty: the host opens the slave (the endpoint), the server reads and writes the
    master."""

    def __init__(self) -> None:
        super().__init__()
        self.endpoint = self.path

    def waitable(self) -> int:
        return self.master

    def take(self) -> bytes | None:
        """What arrived (b"" if nothing); None never: a pty's stream does not restart."""
        try:
            return os.read(self.master, 4096)
        except BlockingIOError:
            return b""
        except OSError:
            raise _Closed from None

    def write(self, data: bytes) -> None:
        """Write everything, or drop what a full, unread pty cannot take (like a bare wire)."""
        view = memoryview(data)
        deadline = time.monotonic() + WRITE_GIVE_UP_S
        while view and time.monotonic() < deadline:
            try:
                n = os.write(self.master, view)
                view = view[n:]
            except BlockingIOError:
                time.sleep(0.001)
            except OSError:
                return

    def hang_up(self, stopping: threading.Event, timeout_s: float = 1.0) -> None:
        """Wait until the host has read what was sent (a hangup would flush it), then close.

        The pty moves written bytes to the slave's input queue asynchronously, so first
        wait (briefly) for them to show up there, then for the queue to empty.
        """
        deadline = time.monotonic() + timeout_s
        arrived_by = time.monotonic() + ARRIVAL_GRACE_S
        seen = False
        while time.monotonic() < deadline and not stopping.is_set():
            if self.unread_by_host() > 0:
                seen = True
            elif seen or time.monotonic() > arrived_by:
                break
            time.sleep(0.001)
        self.close()


class _TcpChannel:
    """A listening socket taking one client at a time (others wait in its backlog until the
    client before them closes)."""

    def __init__(self, host: str) -> None:
        self.listener: socket.socket | None = socket.create_server((host, 0))
        self.conn: socket.socket | None = None
        self.endpoint = f"{host}:{self.listener.getsockname()[1]}"

    def waitable(self) -> socket.socket:
        if self.listener is None:
            raise _Closed
        return self.conn or self.listener

    def take(self) -> bytes | None:
        """What the client sent (b"" if nothing); None when a client came or went (a request
        it left unfinished is dropped)."""
        if self.conn is None:
            if self.listener is None:
                raise _Closed
            self.conn, _ = self.listener.accept()
            self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return None
        try:
            data = self.conn.recv(4096)
        except OSError:
            data = b""
        if not data:
            self._drop_client()
            return None
        return data

    def write(self, data: bytes) -> None:
        """Send everything to the client, or drop it if there is none or it does not read."""
        if self.conn is None:
            return
        try:
            self.conn.settimeout(WRITE_GIVE_UP_S)
            self.conn.sendall(data)
        except OSError:
            pass
        finally:
            if self.conn is not None:
                self.conn.settimeout(None)

    def hang_up(self, stopping: threading.Event) -> None:
        """Close the connection after what was sent (a FIN follows the data) and stop
        listening: the device is gone."""
        if self.conn is not None:
            try:
                self.conn.shutdown(socket.SHUT_WR)
            except OSError:
                pass
        self.close()

    def _drop_client(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None

    def close(self) -> None:
        self._drop_client()
        if self.listener is not None:
            self.listener.close()
            self.listener = None


class PtyServer:
    """A threaded line or frame server on a pty (`start`) or raw TCP (`start_tcp`): bytes in,
    handler, reply bytes (with faults) out.

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
        self._channel: _PtyChannel | _TcpChannel | None = None
        self._wake_r = self._wake_w = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- lifecycle --------------------------------------------------------------
    def start(self) -> str:
        """Open the pty, start serving; returns the endpoint (slave device path)."""
        return self._start(_PtyChannel)

    def start_tcp(self, host: str = LOOPBACK) -> str:
        """Listen on host (a free port), start serving; returns the endpoint HOST:PORT."""
        return self._start(lambda: _TcpChannel(host))

    def _start(self, channel: Callable[[], _PtyChannel | _TcpChannel]) -> str:
        if self._thread is not None:
            raise RuntimeError(f"{self.name}: server already started")
        self._channel = channel()
        self._wake_r, self._wake_w = os.pipe()
        self.endpoint = self._channel.endpoint
        self._thread = threading.Thread(target=self._serve, name=f"pty-{self.name}", daemon=True)
        self._thread.start()
        return self.endpoint

    def stop(self) -> None:
        """Stop serving and close the pty or socket (idempotent)."""
        self._stop.set()
        if self._wake_w >= 0:
            try:
                os.write(self._wake_w, b"x")
            except OSError:
                pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        if self._channel is not None:
            self._channel.close()
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                os.close(fd)
        self._wake_r = self._wake_w = -1

    def __enter__(self) -> PtyServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- serving ----------------------------------------------------------------
    def _serve(self) -> None:
        assert self._channel is not None
        channel = self._channel
        buf = bytearray()
        discarding = False
        while not self._stop.is_set() and not self.disconnected:
            timeout = self.frame_gap_s if (self.terminators is None and buf) else 0.5
            try:
                ready, _, _ = select.select([channel.waitable(), self._wake_r], [], [], timeout)
            except (OSError, ValueError, _Closed):
                return
            if self._wake_r in ready:
                return
            if not ready:
                if self.terminators is None and buf:
                    request, buf = bytes(buf), bytearray()
                    self._dispatch(request)
                continue
            try:
                chunk = channel.take()
            except _Closed:
                return
            if chunk is None:  # a new client, or the last one gone: nothing half-read counts
                buf.clear()
                discarding = False
                continue
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
        assert self._channel is not None
        if out:
            self._channel.write(out)
        if self.faults.should_disconnect():
            self.disconnected = True
            self._channel.hang_up(self._stop)


class PtyDevice:
    """Lifecycle shared by the line-oriented emulators: serve on a pty or raw TCP, stop,
    context manager.

    Subclasses set `self._server` (a PtyServer) and may extend `stop()`.
    """

    _server: PtyServer

    @property
    def endpoint(self) -> str | None:
        """The pty path hosts open, or HOST:PORT on TCP (None before start)."""
        return self._server.endpoint

    @property
    def server(self) -> PtyServer:
        """The pty server (its handler_errors must stay empty)."""
        return self._server

    def start(self) -> str:
        """Serve on a new pty; returns its path."""
        return self._server.start()

    def start_tcp(self, host: str = LOOPBACK) -> str:
        """Serve on raw TCP, listening on host; returns HOST:PORT."""
        return self._server.start_tcp(host)

    def stop(self) -> None:
        """Stop serving and close the pty or socket."""
        self._server.stop()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
