"""`gonio watch RUN`: follow a run in a browser page, while it is measured or after: status,
readings stored of planned, elapsed time and ETA, the stages' positions, raw power against arm
angle and the reduced BSDF per incidence as the readings arrive. The page is served on
127.0.0.1 (a free port unless --port) to whoever holds its key: the first line on stdout is
its address with the key, http://127.0.0.1:PORT/?key=KEY. With the scan session's control
token (--token - on stdin, or --token-file) its pause, resume and abort buttons act on the
scan through its control channel (RUN/control.sock). The viewer changes nothing in the run
directory."""

from __future__ import annotations

import argparse
import functools
import os
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from html import escape
from pathlib import Path

from drivers.user_file import open_user_file
from gonio.errors import GonioError, os_error_text
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
                        "address lets whoever can reach it and holds the URL's key see the run, "
                        "and with a token pause and abort the scan)")
    p.add_argument("--open", action="store_true", help="open the page in the web browser")
    token = p.add_mutually_exclusive_group()
    token.add_argument("--token", metavar="-", type=_stdin_only,
                       help="'-': read the scan session's control token (gonio scan prints it "
                            "on stderr) from stdin's first line, for the pause, resume and "
                            "abort buttons (never on the command line: ps shows it to every "
                            "user)")
    token.add_argument("--token-file", metavar="FILE",
                       help="read the control token from FILE's first line (a file only its "
                            "owner can read)")
    p.add_argument("--until-eof", action="store_true",
                   help="serve until stdin closes, then until an open page has shown the "
                        "run's end (at most a few seconds): how `gonio scan --watch` ties its "
                        "viewer to the scan")
    add_reduce_options(p)
    add_force_option(p)
    p.set_defaults(func=run, reads_run="run")


MAX_TOKEN = 4096  # characters read for a token


def _stdin_only(value: str) -> str:
    """--token's one value, '-' (the token itself would show in ps to every user)."""
    if value != "-":
        raise argparse.ArgumentTypeError(
            "a token on the command line is visible to every user in ps: give --token - "
            "(the token on stdin's first line) or --token-file FILE")
    return value


def _token(args: argparse.Namespace) -> str | None:
    """The control token: stdin's first line for --token -, --token-file's first line, else
    None (GonioError for no token there, or a file other users may read)."""
    if args.token_file is not None:
        where = f"--token-file {args.token_file}"
        line = _token_file_line(args.token_file, where)
    elif args.token == "-":
        where, line = "--token -", sys.stdin.readline(MAX_TOKEN).strip()
    else:
        return None
    if not line:
        raise GonioError(f"{where}: no token on its first line")
    return line


def _token_file_line(path: str, where: str) -> str:
    """The first line of the token file: a regular file of at most MAX_TOKEN bytes (opened
    without blocking, so a FIFO is an error, not a hang), owned by this user and readable by
    no one else, checked on the descriptor that is read."""
    with open_user_file(path, "token file", MAX_TOKEN, GonioError) as fh:
        status = os.fstat(fh.fileno())
        if status.st_uid != os.geteuid():
            raise GonioError(f"{where}: owned by uid {status.st_uid}, not {os.geteuid()} "
                             "(another user wrote it)")
        if status.st_mode & 0o077:
            raise GonioError(f"{where}: other users may read it (chmod 600 it)")
        try:
            return fh.read(MAX_TOKEN).decode("utf-8", "replace").split("\n", 1)[0].strip()
        except OSError as exc:
            raise GonioError(f"{where}: {os_error_text(exc)}") from None


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM (or, with --until-eof, the end of stdin)."""
    from calibration.pipeline import reduce_stored
    from gonio_watch.viewer import serving, until_end_shown

    if not is_loopback(args.bind):
        print(f"gonio watch: warning: --bind {args.bind}: the page is served beyond this "
              "machine: anyone who can reach it and is given its URL sees the run"
              + (" and can pause and abort the scan" if args.token or args.token_file else ""),
              file=sys.stderr, flush=True)
    token = _token(args)
    reduce = functools.partial(reduce_stored, calibration_file=args.calibration,
                               shot_noise_w=args.shot_noise_w,
                               subtract_signature=args.subtract_signature)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    with ExitStack() as stack:
        server = stack.enter_context(serving(args.run, args.bind, args.port, token, reduce))
        print(server.keyed_url, flush=True)
        if args.open:
            stack.enter_context(opened_in_browser(server.keyed_url))
        if args.until_eof:
            threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
        done.wait()
        if args.until_eof:
            server.app.follower.poll()
            until_end_shown(server.app)
    return 0


@contextmanager
def opened_in_browser(url: str) -> Iterator[None]:
    """Open the page in the web browser without putting its key on a command line (a
    browser's arguments show in ps to every user): the browser is given a file only this user
    can read, which sends it on to the URL; the file goes when the block ends."""
    import webbrowser

    fd, name = tempfile.mkstemp(prefix="gonio-watch-", suffix=".html")  # mode 0600
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(f'<!DOCTYPE html><meta http-equiv="refresh" content="0; url={escape(url)}">')
        webbrowser.open(Path(name).as_uri())
        yield
    finally:
        os.unlink(name)


def start_beside(run_dir: Path, token: str | None) -> subprocess.Popen:
    """`gonio watch RUN --until-eof` in a child process of the scan, in a session of its own
    (a Ctrl-C at the terminal is the scan's), given the token on its stdin, which stays open
    while the scan runs; its URL with the key goes to the scan's stderr,
    `gonio scan: watch URL`."""
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
