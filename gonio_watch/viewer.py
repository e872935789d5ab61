"""A viewer of one run: the follower's thread and the HTTP server's, started and stopped
together; and how a viewer tied to a scan (`gonio scan --watch`) knows it may end."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from calibration.reduced import ReducedData
from gonio.store import Run, open_run
from gonio_watch.gate import DEFAULT_LIMITS, Limits
from gonio_watch.reduction import LiveReduction
from gonio_watch.server import WatchApp, WatchServer
from gonio_watch.status import ENDED

LINGER_S = 5.0  # after its scan ended, how long a viewer waits for an open page to see it


@contextmanager
def serving(run_dir: str | Path, host: str = "127.0.0.1", port: int = 0,
            token: str | None = None,
            reduce: Callable[[Run, np.ndarray], ReducedData] | None = None,
            limits: Limits = DEFAULT_LIMITS) -> Iterator[WatchServer]:
    """Follow a run directory and serve its page on (host, port) until the block ends.
    token: the scan session's control token (None: no pause, resume or abort); reduce: how
    to reduce the readings so far (default `gonio reduce`'s); limits: what the server grants
    its connections."""
    run = open_run(run_dir)
    app = WatchApp(run, token, LiveReduction(run, reduce))
    stop = threading.Event()
    app.follower.poll()
    follower = app.follower.follow(stop)
    server = WatchServer(host, port, app, limits)
    thread = threading.Thread(target=server.serve_forever, name="watch-http", daemon=True)
    thread.start()
    try:
        yield server
    finally:
        stop.set()
        server.shutdown()
        server.server_close()
        follower.join()


def until_end_shown(app: WatchApp, linger_s: float = LINGER_S) -> None:
    """Return once the page has been told that the run ended, at once if no page ever asked,
    and at the latest after linger_s (a page left open elsewhere keeps nothing running)."""
    deadline = time.monotonic() + linger_s
    with app.served:
        while app.last_status is not None and app.last_status not in ENDED:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            app.served.wait(left)
