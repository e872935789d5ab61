"""The config fields a device kind declares (`Setting`), and reading them from a
`[devices.<name>]` table with gonio.fields' one-line errors.

A kind lists its settings once; `read_settings` checks a device's table against that list,
so a typo, a wrong type or a value out of bounds is refused the same way for every kind.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivers import byte_link
from gonio.device_kinds.endpoints import LINK_TYPES, read_link
from gonio.device_kinds.filters import read_filters
from gonio.fields import REQUIRED, Fields

#: "string" (one of `choices` if given), "integer" and "number" (within low..high, or one of
#: `choices`), "boolean", "file" (a path relative to the config's folder, made absolute; it
#: must exist), "host" (a device's network address; a wildcard listen address is refused),
#: "port" (a serial port, not a VISA resource string) and "resource" (a VISA resource string
#: of a line device, as PyVISA parses it: gonio.device_kinds.endpoints), "filters" (a filter
#: wheel's table of filters by position: gonio.device_kinds.filters). file, host and filters
#: are required.
TYPES = ("string", "integer", "number", "boolean", "file", "host", "port", "resource",
         "filters")


@dataclass(frozen=True)
class Setting:
    """One config field of a device kind: key, type (TYPES), default (REQUIRED: none), unit,
    bounds (low..high, low excluded if low_open; a number's high is finite) or choices.

    when: (key, value) of an earlier setting this one applies under (a Modbus TCP device has
    a host, an RTU one a port); endpoint: part of where the device is reached (joined by ":"
    in declaration order; may change when a run resumes); recorded: kept in each session's
    record of the device in meta.json; one_of: the name of a group of alternatives of which
    a device gives exactly one (a serial port or a VISA resource), each with no default.
    """

    key: str
    type: str
    default: Any = REQUIRED
    unit: str = ""
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    choices: tuple[Any, ...] = ()
    when: tuple[str, str] | None = None
    endpoint: bool = False
    recorded: bool = False
    one_of: str = ""

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"setting {self.key!r}: type {self.type!r} is not one of {TYPES}")
        if self.type in ("integer", "number") and not self.choices \
                and not math.isfinite(self.high):
            raise ValueError(f"setting {self.key!r}: a number needs a finite upper bound, so "
                             "that no value overflows what uses it")
        if self.one_of and self.default is not None:
            raise ValueError(f"setting {self.key!r}: an alternative of {self.one_of!r} has no "
                             "default")

    def applies(self, values: Mapping[str, Any]) -> bool:
        """True if this setting belongs to a device whose earlier settings are `values`."""
        return self.when is None or values.get(self.when[0]) == self.when[1]

    def read(self, f: Fields, base: Path) -> Any:
        """This setting's value from a device table (relative files resolve against base)."""
        if self.type in ("integer", "number"):
            value = f.number(self.key, self.default, self.low, self.high,
                             integer=self.type == "integer", low_open=self.low_open)
            if self.choices and value not in self.choices:
                raise f.fail(self.key, f"must be one of {', '.join(map(str, self.choices))}; "
                                       f"got {value:g}")
            return value
        if self.type == "boolean":
            return f.boolean(self.key, self.default)
        if self.type == "filters":
            return read_filters(f, self.key)
        value = f.string(self.key, self.default, self.choices)
        if self.type == "file":
            return _existing_file(f, self.key, value, base)
        if self.type == "host":
            return _device_host(f, self.key, value)
        if self.type in LINK_TYPES:
            try:
                return read_link(value, self.type, alternative=bool(self.one_of))
            except ValueError as exc:
                raise f.fail(self.key, str(exc)) from None
        return value

    def value_of(self, text: str) -> Any:
        """A value of this setting from its text in an endpoint (an integer's digits)."""
        return int(text) if self.type == "integer" else text


def read_settings(f: Fields, settings: tuple[Setting, ...], base: Path) -> dict[str, Any]:
    """The values of the settings that apply to the device table `f`, by key, defaults
    filled in, and of each one_of group the one alternative given (none or several: one
    error naming the table); the caller's f.done() then refuses any key no setting asked for."""
    values: dict[str, Any] = {}
    groups: dict[str, list[str]] = {}
    for setting in settings:
        if setting.applies(values):
            value = setting.read(f, base)
            if setting.one_of:
                groups.setdefault(setting.one_of, []).append(setting.key)
                if value is None:
                    continue
            values[setting.key] = value
    for group, keys in groups.items():
        given = [key for key in keys if key in values]
        if len(given) != 1:
            named = " or ".join(repr(key) for key in keys)
            how = "not both" if given else "none is given"
            raise f.error(f"{f.where}: give exactly one of {named} ({group}); {how}")
    return values


def _existing_file(f: Fields, key: str, value: str, base: Path) -> str:
    path = (base / value).resolve()
    if not path.is_file():
        raise f.fail(key, f"no such file {str(path)!r}")
    return str(path)


def _device_host(f: Fields, key: str, host: str) -> str:
    """A device's network address. A wildcard (0.0.0.0, ::) is a listen address, not a
    device's: refused, since emulators never take their listen address from the config."""
    try:
        wildcard = ipaddress.ip_address(host).is_unspecified
    except ValueError:  # a host name
        wildcard = not host.strip()
    if wildcard:
        raise f.fail(key, f"{host!r} is a listen address, not a device's; emulators listen "
                          "on 127.0.0.1 (gonio emulate --bind HOST serves them on another)")
    return host


TIMEOUT_S = Setting("timeout_s", "number", 1.0, unit="s", low=0.0, high=3600.0, low_open=True)
PORT = Setting("port", "port", endpoint=True)
BAUDRATE = Setting("baudrate", "integer", 19200, unit="baud", low=1, high=4_000_000)
LINK = "a serial port or a VISA resource string"
PARITY = Setting("parity", "string", "none", choices=byte_link.PARITIES)
STOPBITS = Setting("stopbits", "number", 1, choices=byte_link.STOPBITS)


def serial_settings(*own: Setting, baudrate: int = 19200,
                    rtscts: bool = False) -> tuple[Setting, ...]:
    """The settings of a device on a line of its own, then its kind's `own`: the reply
    timeout; where it is reached, a serial port or a VISA resource (exactly one); the line
    of a port or an ASRL resource (baudrate, parity, stopbits and flow control, with the
    kind's default baud rate and RTS/CTS)."""
    return (
        TIMEOUT_S,
        dataclasses.replace(PORT, default=None, one_of=LINK),
        Setting("resource", "resource", None, endpoint=True, one_of=LINK),
        dataclasses.replace(BAUDRATE, default=baudrate),
        PARITY,
        STOPBITS,
        Setting("rtscts", "boolean", rtscts),
        Setting("xonxoff", "boolean", False),
        *own,
    )


def only_when(key: str, value: str, *settings: Setting) -> tuple[Setting, ...]:
    """The settings, each applying only when the setting `key` is `value`."""
    return tuple(dataclasses.replace(s, when=(key, value)) for s in settings)
