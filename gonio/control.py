"""The scan control channel: a Unix stream socket RUN_DIR/control.sock (mode 0600) that the scan
process serves while its run is measuring, for `gonio watch` and scripts.

One JSON object per line each way. A request `{"token": T, "command": C}` with C one of
status, pause, resume, abort gets `{"ok": true, "state": S, "readings": N, "planned": M}` (S
the engine's state, gonio.events.State) or `{"ok": false, "error": "<one line>"}`. The token is
new per session (`secrets.token_hex(16)`), printed on stderr only; a request without it gets
"bad token" and nothing is done. Pause acts before the next reading and waits on the channel;
resume continues it; abort ends the run as a Ctrl-C abort does (gonio.run_control).
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import socket
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from gonio.events import ReadingStored, RunStarted
from gonio.run_control import CHANNEL, PauseControl

SOCKET = "control.sock"
ABORT_REASON = "aborted from the control channel"
MAX_REQUEST = 4096  # bytes in one request line
UNIX_PATH_MAX = 107  # sun_path holds 108 bytes with its NUL


class RunStatus:
    """The control channel's subscriber: how many readings are stored of how many planned."""

    def __init__(self) -> None:
        self.readings = 0
        self.planned = 0

    def __call__(self, event: Any) -> None:
        """Follow the counts."""
        if isinstance(event, ReadingStored):
            self.readings += 1
        elif isinstance(event, RunStarted):
            self.readings, self.planned = event.stored, event.planned


class ControlServer:
    """Answers control requests for one run (see the module docstring) on its own threads."""

    def __init__(self, run_dir: Path, control: PauseControl, status: RunStatus,
                 token: str | None = None):
        self.path = run_dir / SOCKET
        self.control, self.status = control, status
        self.token = token or secrets.token_hex(16)
        self._sock = _listen(self.path)
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="control-channel", daemon=True)
        self._thread.start()

    def answer(self, line: bytes) -> dict[str, Any]:
        """The reply to one request line."""
        try:
            request = json.loads(line)
        except ValueError:
            return _error("not a JSON object")
        if not isinstance(request, dict):
            return _error("not a JSON object")
        if not isinstance(request.get("token"), str) or not secrets.compare_digest(
                request["token"], self.token):
            return _error("bad token")
        actions: dict[str, Callable[[], Any]] = {
            "status": lambda: None,
            "pause": lambda: self.control.request_pause(CHANNEL),
            "resume": self.control.request_resume,
            "abort": lambda: self.control.request_abort(ABORT_REASON),
        }
        command = request.get("command")
        if command not in actions:
            return _error(f"unknown command {command!r} (status, pause, resume, abort)")
        try:
            actions[command]()
        except ValueError as exc:
            return _error(str(exc))
        return {"ok": True, "state": self.control.state.value,
                "readings": self.status.readings, "planned": self.status.planned}

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return  # closed
            threading.Thread(target=self._serve, args=(conn,), name="control-connection",
                             daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn, conn.makefile("rb") as lines:
            for line in iter(lambda: lines.readline(MAX_REQUEST), b""):
                reply = (self.answer(line) if line.endswith(b"\n")
                         else _error(f"request longer than {MAX_REQUEST} bytes"))
                try:
                    conn.sendall(json.dumps(reply).encode() + b"\n")
                except OSError:
                    return
                if not line.endswith(b"\n"):
                    return

    def close(self) -> None:
        """Stop answering and remove the socket (one the directory will not let go of stays:
        it refuses connections, and the next session's replaces it)."""
        self._closed.set()
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
        with contextlib.suppress(OSError):
            self.path.unlink()


def _error(message: str) -> dict[str, Any]:
    return {"ok": False, "error": message}


@contextmanager
def _address(path: Path) -> Iterator[str]:
    """An address for bind or connect at `path`: the path itself, or when it is too long for
    sun_path, the same file through the directory's /proc/self/fd entry (Linux)."""
    if len(os.fsencode(str(path))) <= UNIX_PATH_MAX:
        yield str(path)
        return
    dir_fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        yield f"/proc/self/fd/{dir_fd}/{path.name}"
    finally:
        os.close(dir_fd)


def _listen(path: Path) -> socket.socket:
    """A listening socket at path (a stale one from a killed scan replaced), mode 0600 from
    the start: made under umask 177."""
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    mask = os.umask(0o177)
    try:
        with _address(path) as address:
            sock.bind(address)
        sock.listen(8)
    except BaseException:
        sock.close()
        raise
    finally:
        os.umask(mask)
    return sock


def connect(run_dir: str | Path, timeout_s: float = 5.0) -> socket.socket:
    """A client connection to a run's control channel (OSError if the run is not running)."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout_s)
    try:
        with _address(Path(run_dir) / SOCKET) as address:
            sock.connect(address)
    except BaseException:
        sock.close()
        raise
    return sock


@contextmanager
def serving(run_dir: Path, control: PauseControl, status: RunStatus
            ) -> Iterator[ControlServer | None]:
    """Serve the control channel of a run for the duration of a `with` block; its token goes
    to stderr as one line (a socket that cannot be made is a warning: the scan goes on)."""
    try:
        server = ControlServer(run_dir, control, status)
    except OSError as exc:
        print(f"gonio: warning: no control channel ({run_dir / SOCKET}: "
              f"{exc.strerror or exc})", file=sys.stderr, flush=True)
        yield None
        return
    print(f"gonio: control token {server.token} (gonio watch {run_dir} --token - reads it from "
          "stdin, --token-file FILE from a file only you can read)",
          file=sys.stderr, flush=True)
    try:
        yield server
    finally:
        server.close()
