"""The device kinds an instrument config may name as a device's `protocol`, each declared
once: stage, detector, environment sensor, filter wheel or monochromator, its settings, how it
opens, its own config checks.

Config parsing (gonio.config) reads a device's settings from its kind, instrument building
(gonio.instrument) opens it through its kind. sim.device_kinds declares the emulator of
each of these names, with the same role; tests/test_device_kinds.py checks they agree.
Adding a kind is one entry here pointing at its driver module (docs/extending.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gonio.device_kinds.kind import (
    DetectorKind,
    DeviceConfig,
    DeviceKind,
    EnvironmentKind,
    FilterWheelKind,
    MonochromatorKind,
    StageKind,
    all_checks,
)
from gonio.device_kinds.line_checks import check_line, line_agreement
from gonio.device_kinds.modbus import (
    MODBUS_SETTINGS,
    check_register_map,
    check_room_registers,
    check_stage_registers,
    map_full_scales_w,
    modbus_unit,
)
from gonio.device_kinds.serial_line import check_filter_positions, serial_device
from gonio.device_kinds.settings import Setting, serial_settings
from gonio.device_kinds.specs import ESP, PM100, ZABER, DeviceSpec, fixed, register_map_spec

#: a Modbus bus's (or TCP server's) units agree on its line; each has its own register map
MODBUS_LINK = line_agreement("Modbus link", "register_map")

KINDS: dict[str, DeviceKind] = {kind.name: kind for kind in (
    # the ESP301's RS-232 port hands shake by RTS/CTS; its replies carry 5 decimals
    StageKind(name="esp", multi_axis=True, open=serial_device("drivers.esp:EspController"),
              check=check_line, spec=fixed(ESP),
              settings=serial_settings(Setting("decimals", "integer", 5, low=1, high=10),
                                       rtscts=True)),
    # NR3 as the PM100 manual gives it: 1.234567E-06
    DetectorKind(name="pm100", open=serial_device("drivers.pm100:Pm100"), check=check_line,
                 spec=fixed(PM100),
                 settings=serial_settings(Setting("nr3_decimals", "integer", 6, low=1,
                                                  high=14))),
    StageKind(name="modbus-stage", settings=MODBUS_SETTINGS,
              check=all_checks(check_stage_registers, MODBUS_LINK), bus="unit",
              spec=register_map_spec,
              open=modbus_unit("drivers.modbus_stage:ModbusStage")),
    DetectorKind(name="modbus-detector", settings=MODBUS_SETTINGS,
                 check=all_checks(check_register_map, MODBUS_LINK), bus="unit",
                 spec=register_map_spec,
                 config_full_scales_w=map_full_scales_w,
                 open=modbus_unit("drivers.modbus_detector:ModbusDetector")),
    # a daisy chain: the devices on one port share its line, each at its own address
    StageKind(name="zaber", multi_axis=True, open=serial_device("drivers.zaber:ZaberController"),
              check=all_checks(check_line, line_agreement("chain")), bus="address",
              spec=fixed(ZABER),
              settings=serial_settings(Setting("address", "integer", 1, low=1, high=99),
                                       baudrate=115200)),
    # a room temperature and humidity transmitter (the XY-MD02: examples/registermaps)
    EnvironmentKind(name="modbus-environment", settings=MODBUS_SETTINGS,
                    check=all_checks(check_room_registers, MODBUS_LINK), bus="unit",
                    spec=register_map_spec,
                    open=modbus_unit("drivers.modbus_environment:ModbusEnvironment")),
    # a Thorlabs FW102C (6 positions) or FW212C (12): 115200 baud; its filters by position
    FilterWheelKind(name="fw102c", open=serial_device("drivers.fw102c:Fw102cWheel"),
                    check=all_checks(check_line, check_filter_positions),
                    settings=serial_settings(
                        Setting("positions", "integer", 6, choices=(6, 12)),
                        Setting("speed", "string", "high", choices=("high", "slow")),
                        Setting("filters", "filters"), baudrate=115200)),
    # a Newport Cornerstone 130 (2 gratings) or 260 (3): 9600 baud; the grating to use
    MonochromatorKind(name="cornerstone", check=check_line,
                      open=serial_device("drivers.cornerstone:CornerstoneMonochromator"),
                      settings=serial_settings(Setting("grating", "integer", 1, low=1, high=3),
                                               baudrate=9600)),
)}


def device_spec(config: Mapping[str, Any], device: str) -> DeviceSpec:
    """The declared type-B figures of the device `device` of a stored instrument config (its
    raw table); none for a device the config lacks or a kind gonio does not know."""
    devices = config.get("devices", {})
    table = devices.get(device) if isinstance(devices, Mapping) else None
    kind = KINDS.get(table.get("protocol")) if isinstance(table, Mapping) else None
    return kind.spec(table) if kind is not None else DeviceSpec()


def endpoint_keys() -> tuple[str, ...]:
    """Every setting key that is part of some kind's endpoint (what a resume may change)."""
    keys = [s.key for kind in KINDS.values() for s in kind.settings if s.endpoint]
    return tuple(dict.fromkeys(keys))


__all__ = ["KINDS", "DetectorKind", "DeviceConfig", "DeviceKind", "DeviceSpec",
           "EnvironmentKind", "FilterWheelKind", "MonochromatorKind", "Setting", "StageKind",
           "device_spec", "endpoint_keys"]
