"""The Modbus kinds' part: their settings (RTU or TCP, unit, register map), opening a unit,
and the config checks their register maps allow before anything moves.

A Modbus device is described by its register-map file, so a new drive or amplifier of the
same shape needs a map and no code (docs/modbus.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from drivers.byte_link import LineSettings
from drivers.register_map import ROOM_REGISTERS, RegisterMap
from gonio.device_kinds.kind import AxisConfig, DeviceConfig, driver_class
from gonio.device_kinds.settings import (
    BAUDRATE,
    PARITY,
    PORT,
    STOPBITS,
    TIMEOUT_S,
    Setting,
    only_when,
)
from gonio.device_kinds.specs import MAP_KEYS, specification_table
from gonio.errors import ConfigError
from gonio.fields import location

MODBUS_SETTINGS = (
    TIMEOUT_S,
    Setting("transport", "string", choices=("tcp", "rtu"), recorded=True),
    Setting("unit", "integer", 1, low=0, high=247, recorded=True),
    Setting("register_map", "file"),
    *only_when("transport", "tcp",
               Setting("host", "host", endpoint=True),
               Setting("tcp_port", "integer", 502, low=1, high=65535, endpoint=True)),
    # an RTU line's default is the Modbus serial-line specification's: 19200 baud, even parity
    *only_when("transport", "rtu", PORT, BAUDRATE, dataclasses.replace(PARITY, default="even"),
               STOPBITS),
)


def modbus_unit(driver: str) -> Callable[[DeviceConfig], Any]:
    """An opener for the driver class `driver` ("module:Class", a drivers.modbus_transport
    MappedUnit), constructed from the MODBUS_SETTINGS of a device and named after it."""
    def open_unit(dev: DeviceConfig) -> Any:
        s = dev.settings
        timeouts = driver_class("drivers.modbus_transport:ModbusTimeouts")(reply_s=s["timeout_s"])
        if s["transport"] == "tcp":
            address, link = s["host"], {"tcp_port": s["tcp_port"]}
        else:
            line = LineSettings(s["baudrate"], parity=s["parity"], stopbits=s["stopbits"])
            address, link = s["port"], {"line": line}
        return driver_class(driver)(s["transport"], address, s["unit"], s["register_map"],
                                    name=dev.name, timeouts=timeouts, **link)
    return open_unit


def register_map(dev: DeviceConfig, where: str) -> RegisterMap:
    """The device's register map with its [specification] checked (specs.specification_table),
    or a ConfigError naming its register_map field and the map's file and key."""
    try:
        registers = RegisterMap.load(dev.settings["register_map"])
        specification_table(Path(dev.settings["register_map"]))
        return registers
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{location(where, f'devices.{dev.name}', 'register_map')}: "
                          f"{exc}") from None


def check_register_map(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
                       devices: Mapping[str, DeviceConfig]) -> None:
    """A Modbus detector's check: its register map loads."""
    register_map(dev, where)


def check_stage_registers(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
                          devices: Mapping[str, DeviceConfig]) -> None:
    """A Modbus stage's check: the map bounds what the drive accepts, so each of its axes'
    speed, acceleration and limits must encode, before motion."""
    registers = register_map(dev, where)
    for ax in axes:
        for key, register, value in (("speed_deg_s", "velocity", ax.speed_deg_s),
                                     ("accel_deg_s2", "acceleration", ax.accel_deg_s2),
                                     ("limits_deg", "limit_negative", ax.limits_deg[0]),
                                     ("limits_deg", "limit_positive", ax.limits_deg[1])):
            try:
                registers.encode(register, value)
            except (KeyError, ValueError) as exc:
                raise ConfigError(f"{location(where, f'axes.{ax.role}', key)}: the drive's "
                                  f"register map refuses it ({exc})") from None


def check_room_registers(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
                         devices: Mapping[str, DeviceConfig]) -> None:
    """A Modbus environment sensor's check: its map has the temperature and humidity registers
    and its [specification] states both accuracies (every reading's u comes from them)."""
    registers = register_map(dev, where)
    stated = specification_table(Path(dev.settings["register_map"]))
    field = location(where, f"devices.{dev.name}", "register_map")
    try:
        registers.require(ROOM_REGISTERS)
    except ValueError as exc:
        raise ConfigError(f"{field}: {exc}") from None
    for figure in ("temperature_c", "humidity_rel"):
        key = MAP_KEYS[figure][0]
        if key not in stated:
            raise ConfigError(f"{field}: {dev.settings['register_map']} [specification] "
                              f"{key}: missing (the sensor's accuracy, a uniform +-a, gives "
                              f"each reading its uncertainty)")


def map_full_scales_w(dev: DeviceConfig) -> tuple[float, ...]:
    """A Modbus amplifier's ranges as its register map lists them (its gain ranges)."""
    return RegisterMap.load(dev.settings["register_map"]).gain_ranges_w
