"""The client side of a scan's control channel: RUN_DIR/control.sock, a Unix stream socket the
scan process owns while it runs; one JSON object per line each way. A request is
{"token": T, "command": "status" | "pause" | "resume" | "abort"}, a reply {"ok": true,
"state": S, "readings": N, "planned": M} or {"ok": false, "error": "..."}. A socket that
cannot be connected to means the scan is not running."""

from __future__ import annotations

import json
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gonio.control import SOCKET, connect

COMMANDS = ("status", "pause", "resume", "abort")
TIMEOUT_S = 2.0  # a pause is answered at once (it acts at the next point)
MAX_REPLY = 65536


class ControlUnavailable(Exception):
    """No scan answers on the run's control socket (not running, or it went away)."""


@dataclass(frozen=True)
class ControlChannel:
    """The control socket of a run directory and the session's token (None: none given, so
    only whether a scan is there can be asked)."""

    run_dir: Path
    token: str | None

    @property
    def path(self) -> Path:
        """The socket's path."""
        return self.run_dir / SOCKET

    def _connect(self) -> socket.socket:
        """A connection to the socket, through gonio.control's own client route (which
        reaches a path too long for sun_path as the scan binds it)."""
        try:
            return connect(self.run_dir, TIMEOUT_S)
        except OSError as exc:
            why = ("no control socket" if isinstance(exc, FileNotFoundError)
                   else exc.strerror or str(exc))
            raise ControlUnavailable(f"the scan is not running ({why} at {self.path})") from None

    def reachable(self) -> bool:
        """Whether a scan process listens on the socket (connects, sends nothing)."""
        try:
            self._connect().close()
        except ControlUnavailable:
            return False
        return True

    def request(self, command: str) -> dict[str, Any]:
        """Send one command with the token; the reply as a dict (ok false with the scan's
        error, e.g. "bad token"); ControlUnavailable if no scan answers."""
        if command not in COMMANDS:
            raise ValueError(f"unknown control command {command!r}")
        if self.token is None:
            raise ValueError("a control request needs the session's token")
        line = json.dumps({"token": self.token, "command": command}).encode() + b"\n"
        with self._connect() as sock:
            try:
                sock.sendall(line)
                reply = _read_line(sock)
            except OSError as exc:
                raise ControlUnavailable(f"the scan went away ({exc.strerror or exc})") from None
        try:
            out = json.loads(reply)
        except ValueError:
            out = None
        if not isinstance(out, dict) or "ok" not in out:
            return {"ok": False, "error": f"the scan's reply is not the protocol's: {reply[:80]!r}"}
        return out


def _read_line(sock: socket.socket) -> bytes:
    """One reply line (without its newline); ControlUnavailable if the scan closes first."""
    data = b""
    while b"\n" not in data:
        chunk = sock.recv(4096)
        if not chunk:
            raise ControlUnavailable("the scan closed the control connection without a reply")
        data += chunk
        if len(data) > MAX_REPLY:
            break
    return data.split(b"\n", 1)[0]
