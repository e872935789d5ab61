"""Helpers of the held-port tests (drivers.port_lock): holders in processes of their own,
the UUCP lock file of a port, and opens of a port by an unprivileged user."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from drivers.port_lock import uucp_lock_name

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
# a holder in its own process: holds argv[1], says so, releases on its first input line
# (staying alive), ends on its second
HOLDER = """
import sys
from drivers.port_lock import hold
held = hold(sys.argv[1], "first")
print("held", flush=True)
sys.stdin.readline()
held.release()
print("released", flush=True)
sys.stdin.readline()
"""
# an open of the port by an unprivileged user (root's opens pass TIOCEXCL)
OPEN = """
import os, sys
try:
    os.close(os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK))
except OSError as exc:
    print(exc.errno)
else:
    print("opened")
"""
AS_ANOTHER_USER = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"] \
    if os.geteuid() == 0 else []
#: for tests that need an unprivileged user's view of a port
needs_another_user = pytest.mark.skipif(
    os.geteuid() == 0 and shutil.which("setpriv") is None,
    reason="root, and no setpriv to open the port as another user")


def uucp_file(path: str) -> Path:
    """The port's UUCP lock file in /run/lock."""
    return Path("/run/lock") / uucp_lock_name(Path(path))


@contextmanager
def child(script: str, *args: str, env: dict[str, str] | None = None,
          **popen: object) -> Iterator[subprocess.Popen]:
    """A Python process running script with args (stdin and stdout piped); ended after."""
    proc = subprocess.Popen([sys.executable, "-c", script, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env or ENV, **popen)
    try:
        yield proc
    finally:
        proc.stdin.close()
        proc.stdout.close()
        proc.wait(timeout=30)


def said(proc: subprocess.Popen) -> str:
    """The process's next line of output."""
    return proc.stdout.readline().strip()


def tell(proc: subprocess.Popen) -> None:
    """Send the process the line it waits for."""
    proc.stdin.write("\n")
    proc.stdin.flush()


def as_another_user(script: str, *args: str) -> str:
    """What a Python script prints, run by an unprivileged user (this one if not root)."""
    done = subprocess.run([*AS_ANOTHER_USER, sys.executable, "-c", script, *args],
                          capture_output=True, text=True, timeout=30, env=ENV, cwd="/")
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def opens_as_another_user(path: str) -> str:
    """What an open of path by an unprivileged user gives: "opened" or the errno."""
    return as_another_user(OPEN, path)
