"""A driver interrupted while it opens (Ctrl-C in the middle of its first exchange) gives its
port back before the interrupt goes on, so a long-lived process (a queue runner) that carries
on does not keep the port: the ESP and the PM100 on a real pty, in a process of their own."""

from __future__ import annotations

import os
import signal

import pytest
from port_testkit import child, said

from drivers.port_lock import hold

# opens the driver argv[1] on the port argv[2] (a reply wait of an hour: only the interrupt
# ends it); says "interrupted" when Ctrl-C comes, and stays alive until its input line
OPENER = """
import sys
from drivers.esp import EspController
from drivers.pm100 import Pm100
driver = {"esp": EspController, "pm100": Pm100}[sys.argv[1]]
try:
    driver(sys.argv[2], timeout_s=3600.0, name=sys.argv[1])
except KeyboardInterrupt:
    print("interrupted", flush=True)
sys.stdin.readline()
"""


@pytest.mark.parametrize("driver", ["esp", "pm100"])
def test_a_driver_interrupted_while_it_opens_releases_its_port(pty, driver):
    master, path = pty
    slave = os.open(path, os.O_RDWR | os.O_NOCTTY)  # the master's reads wait, not EIO, until
    try:                                            # the driver has opened the port too
        with child(OPENER, driver, path) as opener:
            request = b""
            while not request.endswith((b"\r", b"\n")):  # its first request, then its wait
                request += os.read(master, 256)
            opener.send_signal(signal.SIGINT)
            assert said(opener) == "interrupted"
            with hold(path, "other"):  # the opener still runs: its port is free
                assert opener.poll() is None
    finally:
        os.close(slave)
