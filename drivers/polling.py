"""The drivers' one wait loop: ask the device until it reports what is awaited, a poll period
apart, and give up with a DeviceTimeout naming what was awaited."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

from drivers.base import DeviceTimeout

T = TypeVar("T")


def poll_until(probe: Callable[[], T | None], timeout_s: float, poll_s: float, device: str,
               what: str) -> T:
    """Call `probe` until it returns something other than None and return that; between
    calls wait poll_s. Once a call made after timeout_s (from now) still gives None,
    DeviceTimeout(device, what, timeout_s). What probe raises (a fault the device reports)
    passes through."""
    deadline = time.monotonic() + timeout_s
    while True:
        found = probe()
        if found is not None:
            return found
        if time.monotonic() > deadline:
            raise DeviceTimeout(device, what, timeout_s)
        time.sleep(poll_s)
