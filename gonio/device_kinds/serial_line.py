"""Opening a device on a line of its own (the ESP controllers, the PM100 meters, a Zaber
chain), reached by a serial port or a VISA resource (gonio.device_kinds.line_checks checks
the devices of a daisy chain against each other)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from gonio.device_kinds.kind import DeviceConfig, driver_class


def serial_device(driver: str) -> Callable[[DeviceConfig], Any]:
    """An opener for the driver class `driver` ("module:Class"), constructed as
    `Class(name=, **settings)` from the serial_settings of a device (its `port` or its
    `resource`, the line settings, timeout_s) and any other settings its kind declares (a
    Zaber chain's `address`, the ESP's reply `decimals`): a setting's key is the driver's
    argument."""
    def open_device(dev: DeviceConfig) -> Any:
        return driver_class(driver)(name=dev.name, **dev.settings)
    return open_device
