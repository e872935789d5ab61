"""`gonio watch RUN`: follow a run in a browser page, while it is measured or after: status,
readings stored of planned, elapsed time and ETA, the stages' positions, raw power against arm
angle and the reduced BSDF per incidence as the readings arrive. The page is served on
127.0.0.1 (a free port unless --port) and its address printed on stdout; with the scan
session's --token its pause, resume and abort buttons act on the scan through its control
channel (RUN/control.sock). The viewer changes nothing in the run directory."""

from __future__ import annotations

import argparse
import functools
import signal
import subprocess
import sys
import threading
from pathlib import Path

from gonio.errors import GonioError
from gonio_cli.commands.emulate import is_loopback
from gonio_cli.commands.reduce import add_reduce_options
from gonio_cli.incomplete import add_force_option


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `watch` verb."""
    p = subparsers.add_parser("watch", help="follow a run in a browser page",
                              description=__doc__)
    p.add_argument("run", help="run directory")
    p.add_argument("--port", type=int, default=0,
                   help="port to serve the page on (default: a free one)")
    p.add_argument("--bind", metavar="HOST", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; another "
                        "address shows the run to whoever can reach it, and with --token lets "
                        "them pause and abort the scan)")
    p.add_argument("--open", action="store_true", help="open the page in the web browser")
    p.add_argument("--token", metavar="TOKEN",
                   help="the scan session's control token (gonio scan prints it on stderr), "
                        "for the pause, resume and abort buttons; '-' reads it from stdin's "
                        "first line (a command line is visible to other users in ps)")
    p.add_argument("--until-eof", action="store_true",
                   help="serve until stdin closes, then until an open page has shown the "
                        "run's end (at most a few seconds): how `gonio scan --watch` ties its "
                        "viewer to the scan")
    add_reduce_options(p)
    add_force_option(p)
    p.set_defaults(func=run, reads_run="run")


def _token(value: str | None) -> str | None:
    """--token: as given, or stdin's first line for '-' (GonioError if there is none)."""
    if value != "-":
        return value
    line = sys.stdin.readline().strip()
    if not line:
        raise GonioError("--token -: no token on stdin's first line")
    return line


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM (or, with --until-eof, the end of stdin)."""
    from calibration.pipeline import reduce_stored
    from gonio_watch.viewer import serving, until_end_shown

    if not is_loopback(args.bind):
        print(f"gonio watch: warning: --bind {args.bind}: the page is served beyond this "
              "machine: anyone who can reach it sees the run"
              + (" and can pause and abort the scan" if args.token else ""),
              file=sys.stderr, flush=True)
    token = _token(args.token)
    reduce = functools.partial(reduce_stored, calibration_file=args.calibration,
                               shot_noise_w=args.shot_noise_w,
                               subtract_signature=args.subtract_signature)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    with serving(args.run, args.bind, args.port, token, reduce) as server:
        print(server.url, flush=True)
        if args.open:
            import webbrowser

            webbrowser.open(server.url)
        if args.until_eof:
            threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
        done.wait()
        if args.until_eof:
            server.app.follower.poll()
            until_end_shown(server.app)
    return 0


def start_beside(run_dir: Path, token: str | None) -> subprocess.Popen:
    """`gonio watch RUN --until-eof` in a child process of the scan, in a session of its own
    (a Ctrl-C at the terminal is the scan's), given the token on its stdin, which stays open
    while the scan runs; its URL goes to the scan's stderr, `gonio scan: watch URL`."""
    import gonio_cli

    command = [sys.executable, "-m", gonio_cli.__name__, "watch", str(run_dir), "--until-eof"]
    proc = subprocess.Popen([*command, *(["--token", "-"] if token else [])],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    if token:
        proc.stdin.write(token + "\n")
        proc.stdin.flush()

    def relay_url() -> None:
        url = proc.stdout.readline().strip()
        if url:
            print(f"gonio scan: watch {url}", file=sys.stderr, flush=True)

    threading.Thread(target=relay_url, name="watch-url", daemon=True).start()
    return proc
