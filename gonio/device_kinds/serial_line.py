"""Opening a device on a line of its own (the ESP controllers, the PM100 meters, a Zaber
chain), reached by a serial port or a VISA resource, and the check of a daisy chain's devices
sharing one line."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from gonio.device_kinds.kind import AxisConfig, Check, DeviceConfig, driver_class
from gonio.device_kinds.line_checks import check_line
from gonio.errors import ConfigError
from gonio.fields import location


def serial_device(driver: str) -> Callable[[DeviceConfig], Any]:
    """An opener for the driver class `driver` ("module:Class"), constructed as
    `Class(name=, **settings)` from the serial_settings of a device (its `port` or its
    `resource`, the line settings, timeout_s) and any other settings its kind declares (a
    Zaber chain's `address`, the ESP's reply `decimals`): a setting's key is the driver's
    argument."""
    def open_device(dev: DeviceConfig) -> Any:
        return driver_class(driver)(name=dev.name, **dev.settings)
    return open_device


def chain_check(address: str) -> Check:
    """The check of a kind whose devices naming one port or resource are a daisy chain on one
    line (Zaber's), each answering to its own `address` setting: a line device's check
    (check_line), then every setting but the endpoint and the address (baud rate, parity,
    timeout...) as the chain's first device has it; else one ConfigError naming both devices
    (gonio.device_kinds.endpoints refuses two devices of a chain at one address)."""
    def check(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
              devices: Mapping[str, DeviceConfig]) -> None:
        check_line(dev, axes, where, devices)
        chain = [d for d in devices.values() if d.kind is dev.kind and d.endpoint == dev.endpoint]
        earlier = chain[:chain.index(dev)]
        if not earlier:
            return
        table = f"devices.{dev.name}"
        first = earlier[0]
        for setting in dev.kind.settings:
            key = setting.key
            if setting.endpoint or key == address:
                continue
            mine, theirs = dev.settings.get(key), first.settings.get(key)
            if mine != theirs:
                raise ConfigError(f"{location(where, table, key)}: {json.dumps(mine)} differs "
                                  f"from [devices.{first.name}]'s {json.dumps(theirs)}: both "
                                  f"are on the chain at {dev.endpoint}, one line with one "
                                  "setting")
    return check
