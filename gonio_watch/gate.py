"""The live view's connections, kept cheap whatever clients do: one thread accepts them and
reads each request whole without blocking (a deadline from accept, a size cap, framing errors
answered at once), a fixed pool of workers answers complete requests, one per connection.
A connection costs no thread until its request is in; past the cap the oldest unfinished one
is closed; an accept error (out of descriptors) rests the listener for a growing pause; any
trouble is one rate-limited stderr line, never a traceback (the viewer may share the scan's
terminal)."""

from __future__ import annotations

import errno
import io
import json
import queue
import re
import selectors
import socket
import sys
import threading
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from http import HTTPStatus
from http.client import HTTPException, parse_headers

HEAD_END = re.compile(rb"\r?\n\r?\n")
OUT_OF_RESOURCES = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)
NOTE_EVERY_S = 60.0  # one stderr line per kind of trouble at most this often

Answer = Callable[[socket.socket, bytes, tuple], None]  # a connection, its request, its peer


@dataclass(frozen=True)
class Limits:
    """What one viewer grants its clients."""

    connections: int = 128  # being read at once; past it the oldest unfinished is closed
    workers: int = 4  # threads answering complete requests
    queued: int = 64  # complete requests waiting for a worker; past it: 503
    request_s: float = 5.0  # from accept to a complete request
    write_s: float = 5.0  # to send a reply
    head_bytes: int = 16384
    body_bytes: int = 4096
    backoff_s: tuple[float, float] = (0.01, 1.0)  # first and longest rest after accept errors


DEFAULT_LIMITS = Limits()


class Notices:
    """One stderr line per kind of trouble at most every `every_s` seconds."""

    def __init__(self, prefix: str = "gonio watch", every_s: float = NOTE_EVERY_S):
        self.prefix, self.every_s = prefix, every_s
        self._last: dict[str, float] = {}
        self._lock = threading.Lock()

    def note(self, kind: str, text: str) -> None:
        """Print `PREFIX: warning: TEXT` unless a notice of this kind was printed lately."""
        now = time.monotonic()
        with self._lock:
            if now - self._last.get(kind, -self.every_s) < self.every_s:
                return
            self._last[kind] = now
        try:
            print(f"{self.prefix}: warning: {text}", file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass  # no stderr left to tell


class Refused(Exception):
    """A request answered at once, without a worker: its HTTP status and why."""

    def __init__(self, status: HTTPStatus, why: str):
        super().__init__(why)
        self.status, self.why = status, why


def request_end(data: bytes | bytearray, limits: Limits) -> int | None:
    """Where a complete request (head and Content-Length body) ends in `data`, None while it
    is incomplete; Refused for one that cannot be taken."""
    found = HEAD_END.search(data, 0, limits.head_bytes + 4)
    if found is None:
        if len(data) > limits.head_bytes:
            raise Refused(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, "request head too large")
        return None
    first, _, rest = bytes(data[:found.end()]).partition(b"\n")
    try:
        headers = parse_headers(io.BytesIO(rest))
    except HTTPException as exc:
        raise Refused(HTTPStatus.BAD_REQUEST, f"bad request head ({exc})") from None
    if headers.get("Transfer-Encoding"):
        raise Refused(HTTPStatus.LENGTH_REQUIRED, "a request body needs a Content-Length")
    lengths = {v.strip() for v in headers.get_all("Content-Length") or ()}
    if len(lengths) > 1:
        raise Refused(HTTPStatus.BAD_REQUEST, "conflicting Content-Length headers")
    if not lengths:
        if first.split(b" ", 1)[0] == b"POST":
            raise Refused(HTTPStatus.LENGTH_REQUIRED, "a POST needs a Content-Length")
        return found.end()
    (text,) = lengths
    if not (text.isascii() and text.isdigit()):
        raise Refused(HTTPStatus.BAD_REQUEST, "Content-Length must be a non-negative integer")
    if len(text) > 9 or int(text) > limits.body_bytes:
        raise Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, "a request body here is small")
    end = found.end() + int(text)
    return end if len(data) >= end else None


def quick_reply(status: HTTPStatus, why: str) -> bytes:
    """A complete HTTP reply that closes the connection: status and a JSON error."""
    body = json.dumps({"ok": False, "error": why}).encode()
    return (f"HTTP/1.1 {status.value} {status.phrase}\r\n"
            "Content-Type: application/json; charset=utf-8\r\n"
            f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode() + body


@dataclass(eq=False)
class Pending:
    """A connection whose request is still being read."""

    sock: socket.socket
    fd: int
    peer: tuple
    deadline: float
    data: bytearray = field(default_factory=bytearray)


def _close(sock: socket.socket, reply: bytes = b"") -> None:
    """Send a short reply if the socket takes it now, then close without waiting for the
    peer (what it sent and nobody read is drained first, so that the reply is not reset)."""
    try:
        sock.setblocking(False)
        if reply:
            sock.send(reply)
        sock.shutdown(socket.SHUT_WR)
        for _ in range(16):  # a few buffers' worth, not whatever a peer keeps sending
            if not sock.recv(65536):
                break
    except OSError:
        pass
    sock.close()


class Gate:
    """Accepts on `listener`, reads each request whole, hands it to `answer` on a worker.
    `counts` says what it did (rounds of its loop, accepted, accept_errors (each followed by
    a rest), evicted, expired, refused, answered, failed)."""

    def __init__(self, listener: socket.socket, answer: Answer, notices: Notices,
                 limits: Limits = DEFAULT_LIMITS):
        self.listener, self.answer, self.notices, self.limits = listener, answer, notices, limits
        self.counts: Counter[str] = Counter()
        self._pending: OrderedDict[int, Pending] = OrderedDict()
        self._queue: queue.Queue[tuple[socket.socket, bytes, tuple] | None] = queue.Queue(
            limits.queued)
        self._selector = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._stop = threading.Event()
        self._started, self._done = threading.Event(), threading.Event()
        self._count_lock = threading.Lock()
        self._rest_until: float | None = None  # the listener rests after accept errors
        self._rest_s = 0.0
        self._workers = [threading.Thread(target=self._work, name=f"watch-worker-{k}",
                                          daemon=True) for k in range(limits.workers)]
        for worker in self._workers:
            worker.start()

    def run(self) -> None:
        """Serve until `stop` (the calling thread is the one that accepts and reads)."""
        self._started.set()
        self.listener.setblocking(False)
        self._selector.register(self.listener, selectors.EVENT_READ)
        self._selector.register(self._wake_r, selectors.EVENT_READ)
        try:
            while not self._stop.is_set():
                self.counts["rounds"] += 1
                try:
                    self._round()
                except Exception as exc:  # a bug here must not end the viewer nor print a trace
                    self.notices.note("gate", f"the live view's connections: "
                                              f"{type(exc).__name__}: {exc}")
                    self._stop.wait(self.limits.backoff_s[0])  # and must not spin either
        finally:
            for pending in list(self._pending.values()):
                self._forget(pending)
                _close(pending.sock)
            self._selector.close()
            self._done.set()

    def _round(self) -> None:
        """Wait for something to do, then do it: accept, read, expire, listen again."""
        ready = self._selector.select(self._wait_s())
        for key, _ in ready:  # reads first: what is already in gets in before newcomers
            if key.data is not None and self._pending.get(key.data.fd) is key.data:
                self._read(key.data)
        if any(key.fileobj is self.listener for key, _ in ready):
            self._accept()
        self._expire()
        self._listen_again()

    def stop(self) -> None:
        """End `run` (returns once it has, if it was running) and the workers, once the
        requests already read are answered (each within its write time)."""
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        if self._started.is_set():
            self._done.wait()
        for _ in self._workers:
            self._queue.put(None)
        for worker in self._workers:  # a reply being written is finished, not cut off
            worker.join(self.limits.write_s)
        self._wake_r.close()
        self._wake_w.close()

    def _wait_s(self) -> float:
        """Seconds until the oldest pending request's deadline or the listener's rest ends."""
        oldest = next(iter(self._pending.values()), None)
        ends = [oldest.deadline] if oldest is not None else []
        ends += [self._rest_until] if self._rest_until is not None else []
        return max(min(ends, default=time.monotonic() + 1.0) - time.monotonic(), 0.0)

    def _accept(self) -> None:
        for _ in range(self.limits.connections):  # at most this many per round
            try:
                sock, peer = self.listener.accept()
            except (BlockingIOError, InterruptedError, ConnectionAbortedError):
                return
            except OSError as exc:
                self._back_off(exc)
                return
            self.counts["accepted"] += 1
            self._rest_s = 0.0
            if len(self._pending) >= self.limits.connections:
                self._evict()
            sock.setblocking(False)
            pending = Pending(sock, sock.fileno(), peer, time.monotonic() + self.limits.request_s)
            self._pending[pending.fd] = pending
            self._selector.register(sock, selectors.EVENT_READ, pending)
            self._read(pending)  # a client sends its request as it connects: often it is in

    def _back_off(self, exc: OSError) -> None:
        """After an accept error: close the oldest unfinished connection (a descriptor back)
        and rest the listener, twice as long as last time up to the longest rest."""
        self.counts["accept_errors"] += 1
        first, longest = self.limits.backoff_s
        self._rest_s = min(max(2 * self._rest_s, first), longest)
        self._rest_until = time.monotonic() + self._rest_s
        self._selector.unregister(self.listener)
        if self._pending and exc.errno in OUT_OF_RESOURCES:
            self._evict()
        self.notices.note("accept", f"the live view cannot accept a connection "
                                    f"({exc.strerror or exc}); it waits and tries again")

    def _listen_again(self) -> None:
        if self._rest_until is not None and time.monotonic() >= self._rest_until:
            self._rest_until = None
            self._selector.register(self.listener, selectors.EVENT_READ)

    def _forget(self, pending: Pending) -> None:
        del self._pending[pending.fd]
        self._selector.unregister(pending.fd)

    def _evict(self) -> None:
        """Close the oldest connection still being read (503): the newest gets its place."""
        oldest = next(iter(self._pending.values()))
        self._forget(oldest)
        self.counts["evicted"] += 1
        _close(oldest.sock, quick_reply(HTTPStatus.SERVICE_UNAVAILABLE, "too many connections"))

    def _expire(self) -> None:
        now = time.monotonic()
        while self._pending:
            oldest = next(iter(self._pending.values()))
            if oldest.deadline > now:
                return
            self._forget(oldest)
            self.counts["expired"] += 1
            _close(oldest.sock, quick_reply(HTTPStatus.REQUEST_TIMEOUT, "request too slow"))

    def _refuse(self, pending: Pending, status: HTTPStatus, why: str) -> None:
        self.counts["refused"] += 1
        _close(pending.sock, quick_reply(status, why))

    def _read(self, pending: Pending) -> None:
        try:
            chunk = pending.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            chunk = b""
        if not chunk:
            self._forget(pending)
            pending.sock.close()
            return
        pending.data += chunk
        try:
            end = request_end(pending.data, self.limits)
        except Refused as refused:
            self._forget(pending)
            self._refuse(pending, refused.status, refused.why)
            return
        if end is None:
            return
        self._forget(pending)
        try:
            self._queue.put_nowait((pending.sock, bytes(pending.data[:end]), pending.peer))
        except queue.Full:
            self._refuse(pending, HTTPStatus.SERVICE_UNAVAILABLE, "the viewer is busy")

    def _count(self, what: str) -> None:
        with self._count_lock:
            self.counts[what] += 1

    def _work(self) -> None:
        """A worker: answer complete requests until told to stop (None)."""
        while (item := self._queue.get()) is not None:
            sock, request, peer = item
            try:
                sock.settimeout(self.limits.write_s)
                self.answer(sock, request, peer)
                self._count("answered")
            except OSError:
                self._count("failed")  # the client went away or stopped reading
            except Exception as exc:  # a bug answering one request must not end the worker
                self._count("failed")
                self.notices.note("answer", f"a request to the live view failed: "
                                            f"{type(exc).__name__}: {exc}")
            finally:
                sock.close()
