"""Reading a device through injected byte faults: which reads were refused as garbled and what
the others returned, so a test can check that no wrong number reached the caller."""

from collections.abc import Callable

from drivers.base import ProtocolError


def reads_through_faults(read: Callable[[], float], count: int) -> tuple[list[float], int]:
    """(the values `count` calls of read() returned, how many raised ProtocolError)."""
    values, refused = [], 0
    for _ in range(count):
        try:
            values.append(read())
        except ProtocolError:
            refused += 1
    return values, refused
