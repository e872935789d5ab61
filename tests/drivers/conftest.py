"""Fixtures of the driver tests: a real pseudo-terminal."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from port_testkit import uucp_file


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    """A real pseudo-terminal: (master fd, slave path), the slave open to every user."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.chmod(path, 0o666)
    os.close(slave)
    yield master, path
    os.close(master)
    uucp_file(path).unlink(missing_ok=True)
