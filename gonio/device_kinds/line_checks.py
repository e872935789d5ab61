"""A config's line devices checked against the VISA backend and against each other, once the
whole config is read: the backend can set the line a device asks for, no two devices reach
one device file or resource unless their kinds share a line by design (a Zaber chain's devices
by their addresses, a Modbus RTU bus's units by their unit ids: a kind's `bus` setting), and
the devices sharing one line agree on its settings. A port is one however it is written
(drivers.port_identity.port_key, as the port's hold names it).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence

from drivers.port_identity import port_key
from drivers.visa_link import DEFAULT_LIBRARY, line_resource, visa_library
from gonio.device_kinds.endpoints import LINK_TYPES
from gonio.device_kinds.kind import AxisConfig, Check, DeviceConfig
from gonio.errors import ConfigError
from gonio.fields import location


def check_line(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
               devices: Mapping[str, DeviceConfig]) -> None:
    """A line device's check: the VISA backend can set the line it asks for. pyvisa-py sets no
    mark parity on an ASRL resource (VI_ERROR_NSUP_ATTR_STATE: it compares the state with
    pyserial's constant), so that is refused, pointing at the same port given as `port`."""
    resource = dev.settings.get("resource")
    if resource is None or dev.settings["parity"] != "mark" \
            or not visa_library().endswith(DEFAULT_LIBRARY):
        return
    parsed = line_resource(resource)
    if parsed.interface_type != "ASRL":
        return
    raise ConfigError(f"{location(where, f'devices.{dev.name}', 'parity')}: pyvisa-py cannot "
                      f"set mark parity on {resource} (VI_ERROR_NSUP_ATTR_STATE); give the "
                      f'port as port = "{parsed.board}", or open it through another VISA '
                      f"(GONIO_VISA_LIBRARY=@ivi)")


def line_agreement(line: str, *own: str) -> Check:
    """The check of a kind whose devices share a line, told apart by its `bus` setting (a
    Zaber chain's addresses, a Modbus bus's unit ids): every setting of a device but where it
    is reached, its bus setting and its `own` settings (a Modbus unit's register map) as the
    first device on its line has it (baud rate, parity, timeout...); else one ConfigError
    naming both, the line called `line` ("chain"). Two devices at one address are
    check_shared_links's error."""
    def check(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
              devices: Mapping[str, DeviceConfig]) -> None:
        bus = dev.kind.bus
        first = next(d for d in devices.values() if d.kind.bus == bus and d.line == dev.line)
        if first is dev:
            return
        for setting in dev.kind.settings:
            key = setting.key
            if setting.endpoint or key == bus or key in own:
                continue
            mine, theirs = dev.settings.get(key), first.settings.get(key)
            if mine != theirs:
                raise ConfigError(f"{location(where, f'devices.{dev.name}', key)}: "
                                  f"{json.dumps(mine)} differs from [devices.{first.name}]'s "
                                  f"{json.dumps(theirs)}: both are on the {line} at "
                                  f"{dev.line}, one line with one setting")
    return check


def _reached(dev: DeviceConfig) -> list[tuple[str, str]]:
    """(setting key, what it reaches) for each device file or resource the device is given,
    as drivers.port_identity.port_key names it (a device file with its symlinks resolved, a
    resource in its canonical form)."""
    return [(setting.key, port_key(value)) for setting in dev.kind.settings
            if setting.type in LINK_TYPES
            and (value := dev.settings.get(setting.key)) is not None]


def _told_apart(a: DeviceConfig, b: DeviceConfig) -> bool:
    """Whether two devices on one line are told apart there: kinds with the same bus setting
    (an address, a unit id) and different values of it."""
    bus = a.kind.bus
    return bool(bus) and bus == b.kind.bus and a.settings[bus] != b.settings[bus]


def check_shared_links(devices: Mapping[str, DeviceConfig], where: str) -> None:
    """No two devices reach one device file or resource (an ESP's port given again as the
    meter's ASRL resource), unless they share a bus and are told apart on it: one
    ConfigError naming both."""
    seen: dict[str, list[tuple[DeviceConfig, str]]] = {}
    for dev in devices.values():
        for key, link in _reached(dev):
            for other, other_key in seen.get(link, []):
                if not _told_apart(other, dev):
                    raise ConfigError(f"{where}: [devices.{other.name}] {other_key} and "
                                      f"[devices.{dev.name}] {key} both reach {link}"
                                      f"{_same_address(other, dev)}")
            seen.setdefault(link, []).append((dev, key))


def _same_address(a: DeviceConfig, b: DeviceConfig) -> str:
    """What makes two devices of one bus the same device: their equal address or unit id."""
    bus = a.kind.bus
    if bus and bus == b.kind.bus:
        return f" at {bus} {a.settings[bus]}"
    return ": one device file or resource reaches one device"
