"""Links shared within a process by the devices on one endpoint (the devices of a Zaber daisy
chain on one serial port, the units of a Modbus bus or TCP server), reference counted: the
first device's `open` makes the link, every later one's gets the same link, and the last
`Lease.release` closes it.

A link is made with the settings its first device asks for; a later device that asks for
others (another baud rate on the same wire) is refused with one ValueError naming both devices
and what differs, since one line cannot run two ways at once.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

L = TypeVar("L")


@dataclass
class _Shared(Generic[L]):
    """An open link, the settings it was made with, the device that made it, its users."""

    link: L
    settings: Mapping[str, Any]
    maker: str
    users: int = 0


class Lease(Generic[L]):
    """One device's use of a shared link (`link`) until `release()` (idempotent)."""

    def __init__(self, link: L, release: Callable[[], None]):
        self.link = link
        self._release: Callable[[], None] | None = release

    def release(self) -> None:
        """Give the link back; the last user's release closes it."""
        release, self._release = self._release, None
        if release is not None:
            release()


class SharedLinks(Generic[L]):
    """The links open in this process, by endpoint; `close` closes one nobody uses any more."""

    def __init__(self, close: Callable[[L], None]):
        self._close = close
        self._open: dict[Hashable, _Shared[L]] = {}
        self._lock = threading.Lock()

    def open(self, endpoint: Hashable, settings: Mapping[str, Any], device: str,
             make: Callable[[], L]) -> Lease[L]:
        """`device`'s lease of the link to `endpoint`: the open one if there is one (its
        settings must be `settings`: ValueError otherwise), else the one `make()` opens."""
        with self._lock:
            shared = self._open.get(endpoint)
            if shared is None:
                shared = self._open[endpoint] = _Shared(make(), dict(settings), device)
            elif shared.settings != settings:
                raise ValueError(_disagreement(endpoint, shared, settings, device))
            shared.users += 1
        return Lease(shared.link, lambda: self._drop(endpoint, shared))

    def _drop(self, endpoint: Hashable, shared: _Shared[L]) -> None:
        with self._lock:
            shared.users -= 1
            if shared.users == 0:
                del self._open[endpoint]
                self._close(shared.link)


def _disagreement(endpoint: Hashable, shared: _Shared[Any], settings: Mapping[str, Any],
                  device: str) -> str:
    """`device: ENDPOINT is the line of MAKER, opened with K V; DEVICE gives K V ...`."""
    keys = [k for k in dict.fromkeys([*shared.settings, *settings])
            if shared.settings.get(k) != settings.get(k)]
    theirs = ", ".join(f"{k} {shared.settings.get(k)!r}" for k in keys)
    ours = ", ".join(f"{k} {settings.get(k)!r}" for k in keys)
    return (f"{device}: {endpoint} is the line of {shared.maker}, opened with {theirs}; "
            f"{device} gives {ours} (devices on one line must agree on its settings)")
