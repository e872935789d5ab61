"""The live view's HTTP server: the page and its scripts from the package's assets, and JSON
built from the run directory, nothing else, to whoever holds the viewer's key
(gonio_watch.access); connections are read and answered by gonio_watch.gate.

    GET  /                the page (assets, public: /watch.js, /plot.js, /watch.css)
    GET  /status.json     status, readings stored, planned, incomplete (an ended run's
                          line, else null), elapsed_s, eta_s, positions, suspensions, the
                          control channel's state (gonio_watch.status)
    GET  /data.json?since=N&version=V
                          the raw readings stored after the first N, and the reduced BSDF
                          points changed since reduction version V (gonio_watch.reduction)
    GET  /model.json?keys=30|reflection,...
                          reference curves per panel (gonio_watch.model)
    POST /control/pause | /control/resume | /control/abort
                          relayed to RUN/control.sock with the token given at start

Every request but the public assets' must show the key (401 without it). Every request must
name this server in its Host header (a page elsewhere that points a name of its own at
127.0.0.1 gets nothing); a POST must be JSON from this server's own page (its Origin, when
sent, is this server), so another site cannot pause or abort a scan through the user's
browser. The token stays in this process's memory. One request per connection.
"""

from __future__ import annotations

import io
import ipaddress
import json
import math
import socket
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from gonio.store import Run
from gonio_watch.access import KEY_PARAM, Access
from gonio_watch.control import ControlChannel, ControlUnavailable
from gonio_watch.follow import RunFollower
from gonio_watch.gate import DEFAULT_LIMITS, Gate, Limits, Notices
from gonio_watch.model import ModelCurves
from gonio_watch.reduction import LiveReduction
from gonio_watch.status import Live, status_of

ASSETS = {"/": ("index.html", "text/html; charset=utf-8"),
          "/watch.js": ("watch.js", "text/javascript; charset=utf-8"),
          "/plot.js": ("plot.js", "text/javascript; charset=utf-8"),
          "/watch.css": ("watch.css", "text/css; charset=utf-8")}
PUBLIC = ("/watch.js", "/plot.js", "/watch.css")  # served without the key: nothing of the run
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; base-uri 'none'; "
                               "form-action 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
ACTIONS = ("pause", "resume", "abort")
LIVE_EVERY_S = 0.5  # the scan is asked for its state at most this often
BACKLOG = 128  # connections the kernel holds while the gate is busy
NO_TOKEN = ("pause, resume and abort need the session's control token (the scan prints it "
            "on stderr): start the viewer with `gonio watch RUN --token -` and paste it, or "
            "with `gonio watch RUN --token-file FILE`")
NO_KEY = ("this viewer shows the run only to whoever holds its key: open the URL "
          "`gonio watch` printed (http://HOST:PORT/?key=...)")


def load_assets() -> dict[str, tuple[bytes, str]]:
    """The page's files, by URL path, from the package data."""
    folder = resources.files("gonio_watch") / "assets"
    return {path: ((folder / name).read_bytes(), kind) for path, (name, kind) in ASSETS.items()}


def raw_point(row: dict[str, Any]) -> dict[str, Any]:
    """A stored reading as the raw plot needs it (power None: the detector had no reading)."""
    flags = ["saturated"] * bool(row.get("saturated"))
    flags += [f for f in (row.get("flags") or "").split(",") if f]
    return {"i": row["index"], "kind": row.get("kind"), "side": row.get("side"),
            "ti": row.get("plan_theta_i_deg"), "to": row.get("plan_theta_o_deg"),
            "arm": row.get("arm_deg"), "p": row.get("power_w"), "range": row.get("range_w"),
            "flags": flags}


class WatchApp:
    """What the viewer serves for one run directory."""

    def __init__(self, run: Run, token: str | None, reduction: LiveReduction | None = None):
        self.run = run
        self.notices = Notices()  # the viewer's stderr lines, at most one per kind of trouble
        self.follower = RunFollower(run, self.notices)
        self.reduction = reduction or LiveReduction(run)
        self.model = ModelCurves()
        self.control = ControlChannel(run.path, token)
        self._live_lock = threading.Lock()
        self._live: tuple[float, Live] = (-LIVE_EVERY_S, Live(False))
        self.served = threading.Condition()
        self.last_status: str | None = None  # the status the page was last told

    def live(self) -> Live:
        """The control channel's answer, asked at most every LIVE_EVERY_S."""
        with self._live_lock:
            at, live = self._live
            if time.monotonic() - at < LIVE_EVERY_S:
                return live
            live = self._ask_live()
            self._live = (time.monotonic(), live)
            return live

    def _ask_live(self) -> Live:
        if self.control.token is None:
            return Live(self.control.reachable(), None, NO_TOKEN)
        try:
            reply = self.control.request("status")
        except ControlUnavailable as exc:
            return Live(False, None, str(exc))
        if not reply.get("ok"):
            return Live(True, reply, f"the scan refuses: {reply.get('error')}")
        return Live(True, reply, "")

    def status(self) -> dict[str, Any]:
        """The /status.json document."""
        snap = self.follower.snapshot()
        out = status_of(self.run, snap.meta, snap.rows, self.live(), time.time())
        out.update(damage=snap.damage, torn=snap.torn)
        with self.served:
            self.last_status = out["status"]
            self.served.notify_all()
        return out

    def data(self, since: int, version: int) -> dict[str, Any]:
        """The /data.json document: readings after the first `since` (from 0 if the page has
        more than the file: it was replaced), the reduction since `version`."""
        rows = self.follower.snapshot().rows
        self.reduction.update(rows)
        since = since if since <= len(rows) else 0
        return {"readings": len(rows), "since": since,
                "raw": [raw_point(r) for r in rows[since:]],
                "reduced": self.reduction.since(version)}

    def model_curves(self, keys: list[str]) -> dict[str, Any]:
        """The /model.json document."""
        return self.model.curves(self.reduction.reduced_meta(), keys)

    def command(self, action: str) -> tuple[HTTPStatus, dict[str, Any]]:
        """Relay pause, resume or abort to the scan: (HTTP status, the scan's reply)."""
        if self.control.token is None:
            return HTTPStatus.FORBIDDEN, {"ok": False, "error": NO_TOKEN}
        try:
            reply = self.control.request(action)
        except ControlUnavailable as exc:
            return HTTPStatus.SERVICE_UNAVAILABLE, {"ok": False, "error": str(exc)}
        with self._live_lock:
            self._live = (-LIVE_EVERY_S, self._live[1])  # the next status asks afresh
        return HTTPStatus.OK, reply


class WatchServer:
    """Serves a WatchApp on (host, port) (port 0 takes a free one) to whoever holds its key;
    `serve_forever` on a thread of its own, `shutdown` from another, then `server_close`."""

    def __init__(self, host: str, port: int, app: WatchApp, limits: Limits = DEFAULT_LIMITS):
        family, _, _, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        self.socket = socket.socket(family, socket.SOCK_STREAM)
        try:
            self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.socket.bind(address[:2])
            self.socket.listen(BACKLOG)
        except BaseException:
            self.socket.close()
            raise
        self.server_address = self.socket.getsockname()
        self.app = app
        self.assets = load_assets()
        self.any_host = host in ("0.0.0.0", "::", "")
        self.access = Access(self.port)
        self.gate = Gate(self.socket, self._answer, app.notices, limits)

    def _answer(self, sock: socket.socket, request: bytes, peer: tuple) -> None:
        Handler((sock, request), peer, self)

    def serve_forever(self) -> None:
        """Accept and answer until `shutdown`."""
        self.gate.run()

    def shutdown(self) -> None:
        """End `serve_forever`."""
        self.gate.stop()

    def server_close(self) -> None:
        """Close the listening socket."""
        self.socket.close()

    @property
    def port(self) -> int:
        """The port it listens on."""
        return self.server_address[1]

    @property
    def url(self) -> str:
        """The page's address."""
        host = self.server_address[0]
        return f"http://{f'[{host}]' if ':' in host else host}:{self.port}/"

    @property
    def keyed_url(self) -> str:
        """The page's address with the key: what `gonio watch` prints."""
        return f"{self.url}?{KEY_PARAM}={self.access.key}"

    def names_me(self, host_header: str | None) -> bool:
        """Whether a Host header is this server (its address, or localhost, and its port;
        any name with its port when it listens on every address)."""
        if not host_header:
            return False
        name, _, port = host_header.rpartition(":")
        if port != str(self.port):
            return False
        if self.any_host:
            return True
        mine = self.server_address[0]
        names = {mine, "localhost"} if ipaddress.ip_address(mine).is_loopback else {mine}
        return name.strip("[]") in names


class Handler(BaseHTTPRequestHandler):
    """GET the page, its assets and the JSON documents; POST a control action. Its request
    is (the connection, the request's bytes as the gate read them whole)."""

    server: WatchServer
    protocol_version = "HTTP/1.1"
    set_cookie = False  # the request showed the key in its query: the reply sets the cookie

    def setup(self) -> None:
        """Read the request from its bytes, write the reply to the connection."""
        self.connection, request = self.request
        self.rfile = io.BytesIO(request)
        self.wfile = self.connection.makefile("wb")

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the viewer is no web server log (it may share the scan's terminal)."""

    def _send(self, status: HTTPStatus, body: bytes, kind: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        for name, value in SECURITY_HEADERS.items():
            self.send_header(name, value)
        if self.set_cookie:
            self.send_header("Set-Cookie", self.server.access.set_cookie())
        if status == HTTPStatus.UNAUTHORIZED:
            self.send_header("WWW-Authenticate", 'Key realm="gonio watch"')
        self.send_header("Connection", "close")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: HTTPStatus, data: Any) -> None:
        self._send(status, json.dumps(jsonable(data), allow_nan=False).encode(),
                   "application/json; charset=utf-8")

    def _refuse(self, status: HTTPStatus, why: str) -> None:
        self._json(status, {"ok": False, "error": why})

    def _host_ok(self) -> bool:
        if self.server.names_me(self.headers.get("Host")):
            return True
        self._refuse(HTTPStatus.MISDIRECTED_REQUEST, "this viewer does not serve that host")
        return False

    def _keyed(self, query: dict[str, list[str]]) -> bool:
        shown = self.server.access.shown_by(query, self.headers.get("Cookie"))
        if shown is None:
            self._refuse(HTTPStatus.UNAUTHORIZED, NO_KEY)
            return False
        self.set_cookie = shown == "query"
        return True

    def do_GET(self) -> None:  # noqa: N802 (http.server's name)
        """The page, an asset or a JSON document; 404 for anything else."""
        if not self._host_ok():
            return
        url = urlsplit(self.path)
        query = parse_qs(url.query)
        app = self.server.app
        if url.path not in PUBLIC and not self._keyed(query):
            return
        if url.path in self.server.assets:
            self._send(HTTPStatus.OK, *self.server.assets[url.path])
        elif url.path == "/status.json":
            self._json(HTTPStatus.OK, app.status())
        elif url.path == "/data.json":
            try:
                since, version = _int(query, "since"), _int(query, "version")
            except ValueError as exc:
                self._refuse(HTTPStatus.BAD_REQUEST, str(exc))
                return
            self._json(HTTPStatus.OK, app.data(since, version))
        elif url.path == "/model.json":
            keys = [k for k in query.get("keys", [""])[0].split(",") if k]
            self._json(HTTPStatus.OK, app.model_curves(keys))
        else:
            self._refuse(HTTPStatus.NOT_FOUND, "not found")

    do_HEAD = do_GET

    def do_POST(self) -> None:  # noqa: N802 (http.server's name)
        """A control action from this server's own page."""
        if not self._host_ok() or not self._keyed(parse_qs(urlsplit(self.path).query)):
            return
        origin = self.headers.get("Origin")
        action = urlsplit(self.path).path.removeprefix("/control/")
        if origin is not None and origin != f"http://{self.headers.get('Host')}":
            self._refuse(HTTPStatus.FORBIDDEN, "a control request must come from this page")
        elif not self.headers.get("Content-Type", "").startswith("application/json"):
            self._refuse(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, "a control request is JSON")
        elif not self.path.startswith("/control/") or action not in ACTIONS:
            self._refuse(HTTPStatus.NOT_FOUND, "not found")
        else:
            self._json(*self.server.app.command(action))


def jsonable(data: Any) -> Any:
    """Data with every float that is not finite as None (a stored reading may hold an
    infinity; the browser's JSON has neither it nor NaN)."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: jsonable(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [jsonable(v) for v in data]
    return data


def _int(query: dict[str, list[str]], name: str) -> int:
    """A query's non-negative integer parameter (0 when absent); ValueError naming it."""
    text = query.get(name, ["0"])[0]
    if not text.isdigit():
        raise ValueError(f"{name} must be a non-negative integer, got {text!r}")
    return int(text)
