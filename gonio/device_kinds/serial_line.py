"""Opening a device on a serial line of its own (the ESP controllers, the PM100 meters)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from gonio.device_kinds.kind import DeviceConfig, driver_class


def serial_device(driver: str) -> Callable[[DeviceConfig], Any]:
    """An opener for the driver class `driver` ("module:Class"), constructed as
    `Class(port, baudrate=, timeout_s=, name=, **others)` from the SERIAL_SETTINGS of a
    device and any other settings its kind declares (a Zaber chain's `address`)."""
    def open_device(dev: DeviceConfig) -> Any:
        s = dev.settings
        others = {k: v for k, v in s.items() if k not in ("port", "baudrate", "timeout_s")}
        return driver_class(driver)(s["port"], baudrate=s["baudrate"],
                                    timeout_s=s["timeout_s"], name=dev.name, **others)
    return open_device
