"""The emulated Modbus RTU line: one raw pty whose slave the host opens by path and whose master
the pymodbus server reads and writes on its own event loop (no relay thread, no second pty).

pymodbus's serial server would open a port by name, and a pty's master has none; instead the
server's listener is given `PtyLine.open` in place of its serial connection, so pymodbus's
request handler (framer, decoder, datastore) runs unchanged on a transport over the master.
`PtyMasterTransport.hang_up` cuts the line like a pulled cable once the host has read what
was sent to it (a hangup earlier would flush those bytes).
"""

from __future__ import annotations

import asyncio
import os
import time

from sim.devices.pty_server import ARRIVAL_GRACE_S, PtyPair


class PtyLine(PtyPair):
    """A raw pty pair (sim.devices.pty_server.PtyPair) whose master pymodbus's server serves
    through a PtyMasterTransport."""

    async def open(self, protocol_factory) -> tuple[PtyMasterTransport, asyncio.Protocol]:
        """Stand-in for pymodbus's create_serial_connection: a transport over the master."""
        protocol = protocol_factory()
        return PtyMasterTransport(asyncio.get_running_loop(), protocol, self), protocol


class PtyMasterTransport(asyncio.Transport):
    """asyncio transport on a pty master: the host's bytes go to the protocol as they come,
    the protocol's writes go to the host at once. Bytes that do not fit a host input queue
    that is full are lost, as on a line whose host has stopped reading."""

    HANG_UP_POLL_S = 0.0005

    def __init__(self, loop: asyncio.AbstractEventLoop, protocol: asyncio.Protocol,
                 line: PtyLine):
        super().__init__()
        self._loop, self._protocol, self._line = loop, protocol, line
        self._closed = False
        self._hang_up_since: float | None = None  # armed: cut once the host has read it all
        self._host_seen_queue = False
        loop.add_reader(line.master, self._read_ready)
        loop.call_soon(protocol.connection_made, self)

    def _read_ready(self) -> None:
        try:
            data = os.read(self._line.master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self.close()
            return
        if self._hang_up_since is not None:  # the host writes again: it has read the reply
            self._cut()
        elif data:
            self._protocol.data_received(data)

    def write(self, data: bytes) -> None:
        """Send bytes to the host now."""
        if self._closed or not data:
            return
        try:
            os.write(self._line.master, data)
        except (BlockingIOError, InterruptedError):
            pass  # the host's input queue is full: the bytes are lost
        except OSError:
            self.close()

    def hang_up(self) -> None:
        """Cut the line once the host has read everything written so far: at its next
        write, once its input queue was seen full and is empty again, or after a short grace
        with the queue empty. Returns at once."""
        if self._closed or self._hang_up_since is not None:
            return
        self._hang_up_since = time.monotonic()
        self._watch_hang_up()

    def _watch_hang_up(self) -> None:
        if self._closed:
            return
        waiting = self._line.unread_by_host()
        self._host_seen_queue = self._host_seen_queue or waiting > 0
        grace_over = time.monotonic() - self._hang_up_since > ARRIVAL_GRACE_S
        if not waiting and (self._host_seen_queue or grace_over):
            self._cut()
        else:
            self._loop.call_later(self.HANG_UP_POLL_S, self._watch_hang_up)

    def _cut(self) -> None:
        self.close()
        self._line.close()

    def close(self) -> None:
        """Stop reading and writing (the pty itself stays until the line is closed)."""
        if not self._closed:
            self._closed = True
            self._loop.remove_reader(self._line.master)

    def abort(self) -> None:
        """Same as close (nothing is buffered)."""
        self.close()

    def is_closing(self) -> bool:
        """True once closed."""
        return self._closed

    def get_protocol(self) -> asyncio.BaseProtocol:
        """The protocol fed by this transport."""
        return self._protocol

    def set_protocol(self, protocol: asyncio.BaseProtocol) -> None:
        """Feed another protocol."""
        self._protocol = protocol

    def is_reading(self) -> bool:
        """True while open."""
        return not self._closed

    def get_write_buffer_size(self) -> int:
        """Nothing is buffered: writes go out at once."""
        return 0

    def can_write_eof(self) -> bool:
        """A serial line has no end-of-file."""
        return False
