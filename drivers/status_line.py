"""Status-suffixed exchanges, shared by the ESP300/301 and the PM100 drivers: every message goes
out with the device's error-status query appended (ESP `;TB?`, PM100 `;:SYST:ERR?`), so a
device error comes back with the reply it spoiled and a refused command is seen at once.

Queries are retried after a timeout or a garbled reply (drivers.serial_transport); a command
is sent once, and if its status reply is lost or garbled the error queue is drained (its first
error raised) and the setting read back instead: a command is never re-sent blindly. Settings
(drivers.settings) are read and written through `read_setting` / `write_setting`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from drivers.base import DeviceError, Interlocked, ProtocolError
from drivers.lost_reply import not_resent, sent_once
from drivers.reply_numbers import StrictNumber
from drivers.serial_transport import SerialLineTransport
from drivers.settings import Setting


@dataclass(frozen=True)
class StatusDialect:
    """How one command set reports its error status.

    suffix: appended to every message; status_query: the query alone (drains the queue one
    entry a time, at most queue_depth entries); split(reply, n): the n answers and the status
    text of a reply; status(text): (code, message), or None for a garbled status (code 0 must
    come with the device's no-error text, so a lost separator that merged an answer into the
    status is garbled, not another code); interlocks: the codes that mean an interlock input
    stopped the device (raised as Interlocked).
    """

    suffix: str
    status_query: str
    split: Callable[[str, int], tuple[list[str], str]]
    status: Callable[[str], tuple[int, str] | None]
    queue_depth: int
    interlocks: tuple[int, ...] = ()


class StatusLineDevice:
    """A serial instrument whose every exchange carries its error status. Subclasses give the
    dialect, the transport and their reply readers (`number`, a StrictNumber, and the others
    their settings name)."""

    dialect: StatusDialect
    number: StrictNumber

    def __init__(self, name: str, transport: SerialLineTransport):
        self.name, self.transport = name, transport

    def line_counts(self) -> dict[str, int]:
        """What the line has seen (drivers.base.LineCounts)."""
        return self.transport.line_counts()

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Close the serial port."""
        self.transport.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- exchanges --------------------------------------------------------------
    def query_answers(self, message: str, parsers: Sequence[Callable[[str], Any]],
                      count: int) -> list:
        """Send `message` with the status suffix and return its `count` answers, each read by
        its parser (text when parsers is empty). Retried after a timeout or a garbled reply
        (for messages without side effects, or ones that may safely run twice); a device
        error raises DeviceError (not retried)."""

        def answers(text: str) -> list:
            found = self._checked(message, text, count)
            if not parsers:
                return found
            try:
                return [read(answer) for read, answer in zip(parsers, found, strict=True)]
            except ProtocolError as exc:
                raise ProtocolError(f"{self.name}: reply to {message!r}: {exc}") from None

        return self.transport.query(message + self.dialect.suffix, answers, message)

    def _checked(self, message: str, text: str, count: int) -> list[str]:
        """The answers of a reply, once its status says no error and their number is right."""
        found, status = self.dialect.split(text, count)
        self._raise_if_error(self._status(message, status, text))
        if len(found) != count:
            raise ProtocolError(f"{self.name}: {len(found)} answers to {message!r}, "
                                f"expected {count}: {text!r}")
        return found

    def _status(self, message: str, status: str, text: str) -> tuple[int, str]:
        parsed = self.dialect.status(status)
        if parsed is None:
            raise ProtocolError(f"{self.name}: garbled reply to {message!r}: {text!r}")
        return parsed

    def _raise_if_error(self, status: tuple[int, str]) -> None:
        if status[0] in self.dialect.interlocks:
            raise Interlocked(self.name, *status)
        if status[0] != 0:
            raise DeviceError(self.name, *status)

    def command(self, message: str, confirm: Callable[[], bool] | None = None) -> None:
        """Send a state-changing message once, its status in the same exchange.

        If the status reply is lost or garbled, the error queue is drained (DeviceError for
        its first entry) and `confirm()` (if given) reads the device state back; unconfirmed,
        DriverError: the message itself is never re-sent.
        """
        def settled() -> bool:
            self.errors(raise_first=True)
            return confirm is not None and confirm()

        sent_once(lambda: self._checked(message, self.transport.exchange(
            message + self.dialect.suffix, f"{message!r} status"), 0), settled,
            not_resent(self.name, message))

    def next_error(self) -> tuple[int, str]:
        """Pop the oldest queued error: (code, message); (0, ...) when none is left."""
        query = self.dialect.status_query
        return self.transport.query(query, lambda text: self._status(query, text, text),
                                    f"{query} (error queue)")

    def errors(self, raise_first: bool = False) -> list[tuple[int, str]]:
        """Drain the error queue; raise_first raises DeviceError for the first entry."""
        found = []
        for _ in range(self.dialect.queue_depth):
            code, text = self.next_error()
            if code == 0:
                break
            found.append((code, text))
        if raise_first and found:
            self._raise_if_error(found[0])
        return found

    # -- settings ---------------------------------------------------------------
    def read_setting(self, setting: Setting, address: str = "") -> Any:
        """A setting's value now (address: prefixed to its query, as an ESP axis number)."""
        readers = [getattr(self, reader) for reader in setting.readers]
        answers = self.query_answers(address + setting.query, readers, len(readers))
        return setting.value(*answers) if setting.value else answers[0]

    def write_setting(self, setting: Setting, value: Any, address: str = "") -> None:
        """Send a setting's command once; a lost status is settled by its read-back check."""
        self.command(address + setting.command_for(value), self.confirms(setting, value, address))

    def confirms(self, setting: Setting, value: Any, address: str = "") -> Callable[[], bool]:
        """The read-back test that the device holds value for setting."""
        return lambda: setting.check(value, self.read_setting(setting, address), self.number)
