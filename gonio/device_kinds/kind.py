"""What a device kind is (`StageKind`, `DetectorKind`, `EnvironmentKind`, `FilterWheelKind`,
`MonochromatorKind`), a device of a config (`DeviceConfig`: its name, its kind and the values
of the kind's settings) and an axis of one (`AxisConfig`).

A kind says once what the rest of gonio asks of a protocol: its config settings, how a
device of it opens as `Axis` drivers, a `Detector`, an `EnvironmentSensor` or a
`WavelengthSelector`, and its own config checks.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from drivers.base import Axis, Detector, EnvironmentSensor, WavelengthSelector
from drivers.port_identity import port_key
from gonio.device_kinds.endpoints import LINK_TYPES, socket_resource
from gonio.device_kinds.settings import Setting
from gonio.device_kinds.specs import DeviceSpec, SpecOf, fixed


class StageController(Protocol):
    """A controller driving several axes over one connection (an ESP300/301)."""

    def axis(self, number: int, name: str) -> Axis:
        """The Axis driver of axis `number`, called `name`."""

    def close(self) -> None:
        """Close the connection every axis shares."""


#: A kind's own config check, after the whole config is read: (device, the axes it drives,
#: the config's name for messages, every device of the config by name) -> None, or a
#: ConfigError naming the field.
Check = Callable[["DeviceConfig", Sequence["AxisConfig"], str, Mapping[str, "DeviceConfig"]],
                 None]


def all_checks(*checks: Check) -> Check:
    """One check that runs each of `checks` in turn (a kind's own, then a shared line's)."""
    def check(dev: DeviceConfig, axes: Sequence[AxisConfig], where: str,
              devices: Mapping[str, DeviceConfig]) -> None:
        for each in checks:
            each(dev, axes, where, devices)
    return check


@dataclass(frozen=True)
class AxisConfig:
    """One rotation axis in a role (sample, arm, azimuth, elevation) and its motion profile."""

    role: str
    device: str
    axis: int
    limits_deg: tuple[float, float]
    speed_deg_s: float
    accel_deg_s2: float
    settle_s: float = 0.0
    tolerance_deg: float = 0.01
    home: bool = False
    repeatability_deg: float = 0.0  # 1-sigma scatter of where a move ends (the GUM budget's)


@dataclass(frozen=True, kw_only=True)
class _Kind:
    """What every kind declares: its name (a config's `protocol`), its settings, its check,
    and `bus`: the setting that tells its devices apart on a line they share (a Zaber chain's
    address, a Modbus RTU unit id); devices whose kinds name the same bus setting may share a
    port when their values of it differ (gonio.device_kinds.line_checks), no others; `spec`:
    a device's declared type-B figures from its settings (gonio.device_kinds.specs)."""

    name: str
    settings: tuple[Setting, ...]
    check: Check | None = None
    bus: str = ""
    spec: SpecOf = fixed(DeviceSpec())


@dataclass(frozen=True, kw_only=True)
class StageKind(_Kind):
    """A kind of rotation stage. multi_axis: `open` gives a StageController that every axis
    of the device shares; otherwise `open` gives the Axis itself, one connection per axis."""

    role: ClassVar[str] = "stage"
    open: Callable[[DeviceConfig], StageController | Axis]
    multi_axis: bool = False


@dataclass(frozen=True, kw_only=True)
class DetectorKind(_Kind):
    """A kind of power detector. config_full_scales_w: the ranges a device of this kind
    offers as far as its config tells, before it is opened (a register map's gain ranges)."""

    role: ClassVar[str] = "detector"
    open: Callable[[DeviceConfig], Detector]
    config_full_scales_w: Callable[[DeviceConfig], tuple[float, ...]] | None = None


@dataclass(frozen=True, kw_only=True)
class EnvironmentKind(_Kind):
    """A kind of room temperature and humidity sensor, read at every reading (a config has
    at most one); its `spec` states its temperature_c and humidity_rel accuracy."""

    role: ClassVar[str] = "environment"
    open: Callable[[DeviceConfig], EnvironmentSensor]


@dataclass(frozen=True, kw_only=True)
class FilterWheelKind(_Kind):
    """A kind of motorised filter wheel: it selects a wavelength by turning the filter centred
    on it (the config's `filters`) into the beam."""

    role: ClassVar[str] = "filter_wheel"
    open: Callable[[DeviceConfig], WavelengthSelector]


@dataclass(frozen=True, kw_only=True)
class MonochromatorKind(_Kind):
    """A kind of monochromator: it selects a wavelength by turning its grating."""

    role: ClassVar[str] = "monochromator"
    open: Callable[[DeviceConfig], WavelengthSelector]


DeviceKind = StageKind | DetectorKind | EnvironmentKind | FilterWheelKind | MonochromatorKind


@dataclass(frozen=True)
class DeviceConfig:
    """One physical controller, drive or meter: its kind and the values of the kind's
    settings that apply to it (`settings`, by key; defaults filled in)."""

    name: str
    kind: DeviceKind
    settings: Mapping[str, Any]

    @property
    def protocol(self) -> str:
        """The kind's name, as the config spells it."""
        return self.kind.name

    def _applied(self, flag: str) -> list[Setting]:
        return [s for s in self.kind.settings if getattr(s, flag) and s.key in self.settings]

    @property
    def endpoint(self) -> str:
        """Where the device is reached: a serial port, or host:port."""
        return ":".join(str(self.settings[s.key]) for s in self._applied("endpoint"))

    @property
    def line(self) -> str:
        """What the device's line is known by, however the config writes it: its port or
        resource as the port's hold names it (drivers.port_identity.port_key: a symlink and
        the device file it names are one line), else its endpoint (a TCP server's host:port)."""
        links = [self.settings[s.key] for s in self._applied("endpoint") if s.type in LINK_TYPES]
        return port_key(links[0]) if links else self.endpoint

    def endpoint_values(self, endpoint: str) -> dict[str, Any]:
        """The endpoint settings that point this device at `endpoint` (an `endpoint` string
        of the same shape, e.g. an emulator's), by key."""
        keys = self._applied("endpoint")
        parts = endpoint.rsplit(":", len(keys) - 1) if len(keys) > 1 else [endpoint]
        return {s.key: s.value_of(part) for s, part in zip(keys, parts, strict=True)}

    @property
    def networked(self) -> bool:
        """True if the device is reached at a network port its emulator listens on too (a
        host setting applies, or its resource is a TCPIP SOCKET one)."""
        return any(s.type == "host" or (s.type == "resource"
                                        and socket_resource(self.settings[s.key]))
                   for s in self._applied("endpoint"))

    @property
    def recorded(self) -> dict[str, Any]:
        """The settings each session's record of the device keeps (a Modbus transport, unit)."""
        return {s.key: self.settings[s.key] for s in self._applied("recorded")}


def driver_class(path: str) -> Any:
    """The class (or other attribute) `module:name`, imported when first needed: opening a
    device loads its driver (and pymodbus) only then."""
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)
