"""A pty server for a device that also speaks unprompted: Zaber's alerts go out when a motion
ends, not only when the next command comes.

While the emulator has an alert pending and its clock runs in real time (a finite, non-zero
time scale), a watcher thread asks it every `poll_s` for the alerts now due and writes them.
A clock that moves only when read (a frozen or ticking clock) is never read from here: its
alerts go out with the reply to the command during which the motion is seen to have ended.
A reply and the lines handled with it are written as one, never split by an alert.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from sim.devices.pty_server import Handler, PtyServer

POLL_S = 0.002  # real seconds between two looks for an ended motion


class AlertingPtyServer(PtyServer):
    """A PtyServer that writes the lines `unsolicited()` returns between replies.

    waiting() says whether an alert may be due (cheap: it reads no clock); notify() wakes the
    watcher when a motion that will end in an alert has begun.
    """

    def __init__(self, handler: Handler, *, unsolicited: Callable[[], bytes | None],
                 waiting: Callable[[], bool], poll_s: float = POLL_S, **options):
        super().__init__(handler, **options)
        self.unsolicited, self.waiting, self.poll_s = unsolicited, waiting, poll_s
        self._io = threading.Lock()  # one writer at a time: a reply, or the watcher's alerts
        self._wake = threading.Event()
        self._watcher: threading.Thread | None = None

    def _start(self, channel: Callable[[], Any]) -> str:
        """Serve on the channel (a pty or TCP: start and start_tcp alike), and watch for
        alerts; returns the endpoint."""
        endpoint = super()._start(channel)
        self._watcher = threading.Thread(target=self._watch, name=f"alerts-{self.name}",
                                         daemon=True)
        self._watcher.start()
        return endpoint

    def stop(self) -> None:
        """Stop watching and serving (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self._watcher is not None:
            self._watcher.join(timeout=5.0)
        super().stop()

    def notify(self) -> None:
        """A motion that ends in an alert has begun: look for its end."""
        self._wake.set()

    def _dispatch(self, request: bytes) -> None:
        with self._io:
            super()._dispatch(request)

    def _watch(self) -> None:
        while not self._stop.is_set():
            if not self.waiting():
                self._wake.wait()
                self._wake.clear()
                continue
            if self._stop.wait(self.poll_s):
                return
            with self._io:
                if not self.disconnected:
                    try:
                        self._send(self._call(self.unsolicited))
                    except OSError:  # the line closed under it: the emulator is stopping
                        return
