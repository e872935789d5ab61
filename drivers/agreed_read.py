"""Reading a value the same way twice: the line protocols without a checksum (the Cornerstone's
WAVE?, a 12-position filter wheel's pos?) carry numbers whose shape survives a dropped digit
(632.8 read as 62.8), so such a read is taken only when two reads in a row agree."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from drivers.base import ProtocolError

T = TypeVar("T")


def agreed(read: Callable[[], T], device: str, what: str, reads: int = 4) -> T:
    """read() until two reads in a row give the same value, and return it; ProtocolError
    naming what was read when `reads` reads (at least 2) give no such pair."""
    last = read()
    seen = [last]
    for _ in range(max(reads, 2) - 1):
        value = read()
        if value == last:
            return value
        last = value
        seen.append(value)
    raise ProtocolError(f"{device}: {what} answered {', then '.join(map(str, seen))}")
