"""Waiting in tests without wall-clock bounds: poll a condition until it holds, with a
generous timeout that only guards against a hang and never decides a healthy run."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

#: seconds after which a wait that never came true fails the test (a hang, not a slow machine)
HANG_S = 60.0


def wait_until(predicate: Callable[[], T], timeout_s: float = HANG_S,
               what: str = "the condition", poll_s: float = 0.002) -> T:
    """Call predicate until it returns a true value and return that value; AssertionError
    naming `what` if it has not come true after timeout_s (real seconds, a hang guard)."""
    guard = time.monotonic() + timeout_s
    while not (value := predicate()):
        assert time.monotonic() < guard, f"{what}: not true after {timeout_s:g} s"
        time.sleep(poll_s)
    return value
