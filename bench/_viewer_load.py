"""Load on a live view, for the soak: pages polling it as its watch.js does (the keyed page
once, then /status.json and /data.json?since=N&version=V every second with the cookie the
page visit set) and idle connections held open against its connection cap (those it closes
are opened again once a second)."""

from __future__ import annotations

import http.client
import json
import resource
import selectors
import socket
import threading
from collections import Counter
from urllib.parse import urlsplit

POLL_S = 1.0  # watch.js's POLL_MS


def _get(port: int, path: str, cookie: str | None) -> tuple[int, str | None, bytes]:
    """(status, Set-Cookie, body) of one GET on a connection of its own (the viewer answers
    one request per connection)."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        conn.request("GET", path, headers={"Cookie": cookie} if cookie else {})
        reply = conn.getresponse()
        return reply.status, reply.getheader("Set-Cookie"), reply.read()
    finally:
        conn.close()


class Pages:
    """`n` pages open on the viewer at `url` (its keyed URL), each polling on a thread;
    `counts`: polls answered, refused (an HTTP status other than 200), failed (the
    connection closed unanswered), gone (the viewer ended with its scan: the page stops)."""

    def __init__(self, url: str, n: int):
        self.url, self.counts = urlsplit(url), Counter()
        self.started = threading.Barrier(n + 1)
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._threads = [threading.Thread(target=self._page, daemon=True) for _ in range(n)]
        for thread in self._threads:
            thread.start()
        self.started.wait()

    def _count(self, what: str) -> None:
        with self._lock:
            self.counts[what] += 1

    def _page(self) -> None:
        port = self.url.port
        try:
            status, cookie, _ = _get(port, f"/?{self.url.query}", None)
        except OSError:
            status, cookie = 0, None
        self.started.wait()
        if status != 200 or cookie is None:
            self._count("refused")
            return
        cookie = cookie.split(";")[0]
        since = version = 0
        while not self._stop.wait(POLL_S):
            try:
                status, _, _ = _get(port, "/status.json", cookie)
                data_status, _, body = _get(port, f"/data.json?since={since}&version={version}",
                                            cookie)
            except ConnectionRefusedError:
                self._count("gone")  # the viewer ended with its scan: the page stops asking
                return
            except OSError:
                self._count("failed")
                continue
            if status != 200 or data_status != 200:
                self._count("refused")
                continue
            doc = json.loads(body)
            since, version = doc["readings"], doc["reduced"].get("version", version)
            self._count("polls")

    def close(self) -> None:
        """Close the pages."""
        self._stop.set()
        for thread in self._threads:
            thread.join()


class IdleConnections:
    """`n` connections to the viewer at `url` that never send a byte; those it closes are
    opened again once a second. The soft descriptor limit is raised to the hard one."""

    def __init__(self, url: str, n: int):
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        if soft < hard:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
        self.port, self.n, self.closed_by_viewer = urlsplit(url).port, n, 0
        self._selector = selectors.DefaultSelector()
        self._stop = threading.Event()
        self._top_up()
        self._thread = threading.Thread(target=self._hold, daemon=True)
        self._thread.start()

    def _top_up(self) -> None:
        """Open connections up to n (none once the viewer is gone: its scan ended)."""
        for _ in range(self.n - len(self._selector.get_map())):
            try:
                sock = socket.create_connection(("127.0.0.1", self.port))
            except ConnectionRefusedError:
                return
            self._selector.register(sock, selectors.EVENT_READ)

    def _hold(self) -> None:
        while not self._stop.wait(1.0):
            for key, _ in self._selector.select(0):
                self._selector.unregister(key.fileobj)
                key.fileobj.close()
                self.closed_by_viewer += 1
            self._top_up()

    def close(self) -> None:
        """Close every connection."""
        self._stop.set()
        self._thread.join()
        for key in list(self._selector.get_map().values()):
            key.fileobj.close()
        self._selector.close()
