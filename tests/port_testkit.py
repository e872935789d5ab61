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

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
HOLDING = """
import sys
{take}
print("held", flush=True)
sys.stdin.readline()
{give_back}
print("released", flush=True)
sys.stdin.readline()
"""


def holding(take: str, give_back: str) -> str:
    """A holder's script: takes a port (the statements `take`), says "held", gives it back
    (`give_back`) on its first input line and says "released", staying alive; ends on its
    second."""
    return HOLDING.format(take=take, give_back=give_back)


# a holder in its own process of argv[1]
HOLDER = holding('from drivers.port_lock import hold\nheld = hold(sys.argv[1], "first")',
                 "held.release()")
# tries to hold argv[1] as "x"; prints the refusal, or "held"
TRY_HOLD = """
import sys
from drivers.port_lock import PortInUse, hold
try:
    hold(sys.argv[1], "x").release()
except PortInUse as exc:
    print(exc)
else:
    print("held")
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


def elsewhere(script: str, *args: str, user: list[str] | None = None) -> str:
    """What a Python script prints, run with args in another process (as `user`, a command
    prefix that changes it, if given)."""
    done = subprocess.run([*(user or []), sys.executable, "-c", script, *args],
                          capture_output=True, text=True, timeout=30, env=ENV, cwd="/")
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def as_another_user(script: str, *args: str) -> str:
    """What a Python script prints, run by an unprivileged user (this one if not root)."""
    return elsewhere(script, *args, user=AS_ANOTHER_USER)


def opens_as_another_user(path: str) -> str:
    """What an open of path by an unprivileged user gives: "opened" or the errno."""
    return as_another_user(OPEN, path)
