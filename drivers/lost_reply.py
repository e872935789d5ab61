"""The drivers' one rule for a state-changing message whose reply is lost: it is sent once and
never re-sent; when its reply is lost or garbled, a read-back of the device's state (each
driver's own query: a setting, the motion status, the position) settles whether the device
took it."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from drivers.base import DeviceTimeout, DriverError, ProtocolError

T = TypeVar("T")
LOST = (DeviceTimeout, ProtocolError)  # no reply in time, or one that cannot be read


def sent_once(send: Callable[[], T], taken: Callable[[], bool],
              unconfirmed: Callable[[Exception], Exception]) -> T | None:
    """send() once and return its reply. If the reply is lost or garbled, taken() reads the
    device back: None when it took the message, else the error unconfirmed(lost) is raised
    (the lost reply's own error when unconfirmed returns it)."""
    try:
        return send()
    except LOST as exc:
        if taken():
            return None
        error = unconfirmed(exc)
        if error is exc:
            raise
        raise error from exc


def not_resent(device: str, message: str) -> Callable[[Exception], DriverError]:
    """The error for a message of `device` whose lost reply the read-back did not confirm."""
    return lambda lost: DriverError(f"{device}: {message!r} not confirmed ({lost}); not re-sent")


def reraise(lost: Exception) -> Exception:
    """Unconfirmed: the lost reply's own error (a timeout, a garbled reply) stands."""
    return lost
