"""Opening a device on a line of its own (the ESP controllers, the PM100 meters, a Zaber
chain, a filter wheel, a monochromator), reached by a serial port or a VISA resource
(gonio.device_kinds.line_checks checks the devices of a daisy chain against each other), and
a filter wheel's check of its filters against its positions."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from gonio.device_kinds.kind import AxisConfig, DeviceConfig, driver_class
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


def check_filter_positions(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
                           devices: Mapping[str, DeviceConfig]) -> None:
    """A filter wheel's filters sit at its positions (1..`positions`): else one ConfigError
    naming the filter."""
    count = dev.settings["positions"]
    for position, _, _ in dev.settings["filters"]:
        if position > count:
            raise ConfigError(f"{location(where, f'devices.{dev.name}', f'filters.{position}')}"
                              f": position {position} is beyond the wheel's {count} positions "
                              "(positions)")
