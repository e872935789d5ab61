"""A config's line devices checked against the VISA backend and against each other, once the
whole config is read: the backend can set the line a device asks for, and no two devices reach
one device file or resource unless their kinds share a line by design (a Zaber chain's devices
by their addresses, a Modbus RTU bus's units by their unit ids: a kind's `bus` setting).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from drivers.port_identity import device_path
from drivers.visa_link import DEFAULT_LIBRARY, line_resource, visa_library
from gonio.device_kinds.endpoints import LINK_TYPES
from gonio.device_kinds.kind import AxisConfig, DeviceConfig
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


def _reached(dev: DeviceConfig) -> list[tuple[str, str]]:
    """(setting key, what it reaches) for each device file or resource the device is given:
    a device file with its symlinks resolved, else the resource's name as PyVISA writes it."""
    out = []
    for setting in dev.kind.settings:
        value = dev.settings.get(setting.key)
        if setting.type in LINK_TYPES and value is not None:
            path = device_path(value)
            if path is not None:
                out.append((setting.key, str(path)))
            elif setting.type == "resource":
                out.append((setting.key, str(line_resource(value))))
            else:
                out.append((setting.key, value))
    return out


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
            for other, other_key in seen.get(link.casefold(), []):
                if not _told_apart(other, dev):
                    raise ConfigError(f"{where}: [devices.{other.name}] {other_key} and "
                                      f"[devices.{dev.name}] {key} both reach {link}"
                                      f"{_same_address(other, dev)}")
            seen.setdefault(link.casefold(), []).append((dev, key))


def _same_address(a: DeviceConfig, b: DeviceConfig) -> str:
    """What makes two devices of one bus the same device: their equal address or unit id."""
    bus = a.kind.bus
    if bus and bus == b.kind.bus:
        return f" at {bus} {a.settings[bus]}"
    return ": one device file or resource reaches one device"
