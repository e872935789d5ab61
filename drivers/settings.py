"""Device settings declared one line each, in the manner of PyMeasure's `control`, with gonio's
stronger meaning: the command is sent once and never re-sent blindly; when its status is lost
the setting is read back and the rule declared with it decides whether the command was taken.

A `Setting` on a driver class is a property: reading it sends the query, assigning it sends
the command. The class (the host) does the exchanges: `read_setting(setting)` and
`write_setting(setting, value)` (drivers.status_line for the ESP and the PM100, the
controller's `get` / `set` for Zaber, whose values are integers: its hosts check with no
number shape).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from drivers.reply_numbers import StrictNumber

# (sent, read back, the host's number shape or None for integer values) -> taken
Check = Callable[[Any, Any, StrictNumber | None], bool]


def exactly(sent: Any, got: Any, number: StrictNumber | None) -> bool:
    """The read-back is the value sent (integers, flags, codes)."""
    return got == sent


def to_reply_precision(sent: float, got: float | None, number: StrictNumber) -> bool:
    """The read-back is the value sent as the reply shows it: within half a unit of its last
    place (VA 12.345678 reads back 12.34568 on five decimals)."""
    return got is not None and abs(got - sent) <= number.half_unit(sent) * (1 + 1e-9)


class SettingHost(Protocol):
    """A driver that owns settings: it sends their queries and commands."""

    def read_setting(self, setting: Setting) -> Any:
        """The setting's value now, from its query."""

    def write_setting(self, setting: Setting, value: Any) -> None:
        """Send the setting's command once; settle a lost status by the setting's check."""


@dataclass(frozen=True)
class Setting:
    """One setting: its query, its command ("{}" takes format(value)), the host's reply
    readers for the query's answers (by attribute name: "number", "integer", "flag"), the
    format of the value in the command, the read-back check, and what it is. value: the
    setting's value from the answers, when there are several (else the one answer)."""

    query: str
    command: str
    reply: str | tuple[str, ...]
    format: Callable[[Any], str]
    check: Check
    doc: str = ""
    value: Callable[..., Any] | None = None

    @property
    def readers(self) -> tuple[str, ...]:
        """The names of the host's readers, one per answer of the query."""
        return (self.reply,) if isinstance(self.reply, str) else self.reply

    def command_for(self, value: Any) -> str:
        """The command that sets value."""
        return self.command.format(self.format(value))

    def __get__(self, host: SettingHost | None, owner: type | None = None) -> Any:
        return self if host is None else host.read_setting(self)

    def __set__(self, host: SettingHost, value: Any) -> None:
        host.write_setting(self, value)
