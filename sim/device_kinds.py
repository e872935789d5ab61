"""The device kinds sim emulates, each declared once: its name (a config's `protocol`),
stage, detector, environment sensor, filter wheel or monochromator, the factory that starts
its emulator, the fault keys only it acts on and the [sim.devices.<name>] keys that say what
its emulator is (a PM100's console and head, a Zaber product's device id, firmware and saved
comm.alert).

gonio.device_kinds declares the same names with the same roles (how the real devices are
configured and opened); sim never imports it, and tests/test_device_kinds.py checks that the
two registries agree. Adding a kind is one entry here pointing at its emulator module
(docs/extending.md).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

from sim.devices.cornerstone import CornerstoneEmulator
from sim.devices.esp import EspEmulator
from sim.devices.faults import KIND_FAULTS
from sim.devices.fw102c import Fw102cEmulator
from sim.devices.photodiode import SimConfigError
from sim.devices.pm100 import Pm100Emulator
from sim.devices.pm100_models import CONSOLES, HEADS
from sim.devices.zaber import ZaberEmulator
from sim.devices.zaber_device import IDENTITY_CHECKS
from sim.emulator_factories import (
    DetectorFactory,
    EnvironmentFactory,
    SelectorFactory,
    StageFactory,
    chain_on_pty,
    controller_on_pty,
    line_of,
    meter_on_pty,
    modbus_detector_unit,
    modbus_environment_unit,
    modbus_stage_units,
    selector_on_pty,
)

#: a [sim.devices.<name>] key's check of its value: None, or what is wrong with it
SettingCheck = Callable[[Any], str | None]
#: what a port or resource is known by (a device file and a symlink to it: one line)
LineKey = Callable[[str], Hashable]


def one_of(choices: tuple[str, ...]) -> SettingCheck:
    """The check of a key that takes one of `choices`."""
    def problem(value: Any) -> str | None:
        return None if value in choices else f"{value!r} is not one of {', '.join(choices)}"
    return problem


@dataclass(frozen=True, kw_only=True)
class _Kind:
    """What every emulated kind declares: its name, the fault keys only it acts on, and the
    [sim.devices.<name>] keys that say what its emulator pretends to be, each with the check
    of its value."""

    name: str
    own_faults: tuple[str, ...] = ()
    settings: Mapping[str, SettingCheck] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class StageEmulator(_Kind):
    """An emulated stage kind: `start` serves a device's emulator with all its axes;
    chained: the kind's devices that name one port or resource are a daisy chain, started
    together (the first, its `mates` the others) by one emulator on one line."""

    role: ClassVar[str] = "stage"
    start: StageFactory
    chained: bool = False


@dataclass(frozen=True, kw_only=True)
class DetectorEmulator(_Kind):
    """An emulated detector kind: `start` serves a device's emulator lit by the bench."""

    role: ClassVar[str] = "detector"
    start: DetectorFactory


@dataclass(frozen=True, kw_only=True)
class EnvironmentEmulator(_Kind):
    """An emulated environment-sensor kind: `start` serves a device's emulator reading the
    bench's room ([sim.room])."""

    role: ClassVar[str] = "environment"
    start: EnvironmentFactory


@dataclass(frozen=True, kw_only=True)
class FilterWheelEmulator(_Kind):
    """An emulated filter-wheel kind: `start` serves a device's emulator."""

    role: ClassVar[str] = "filter_wheel"
    start: SelectorFactory


@dataclass(frozen=True, kw_only=True)
class MonochromatorEmulator(_Kind):
    """An emulated monochromator kind: `start` serves a device's emulator."""

    role: ClassVar[str] = "monochromator"
    start: SelectorFactory


SelectorEmulator = FilterWheelEmulator | MonochromatorEmulator
EmulatorKind = StageEmulator | DetectorEmulator | EnvironmentEmulator | SelectorEmulator

KINDS: dict[str, EmulatorKind] = {kind.name: kind for kind in (
    StageEmulator(name="esp", start=controller_on_pty(EspEmulator, "estop"),
                  own_faults=("interlock",)),
    DetectorEmulator(name="pm100", start=meter_on_pty(Pm100Emulator),
                     own_faults=("invalid_prob",),
                     settings={"model": one_of(tuple(CONSOLES)), "sensor": one_of(tuple(HEADS))}),
    StageEmulator(name="modbus-stage", start=modbus_stage_units, own_faults=("interlock",)),
    DetectorEmulator(name="modbus-detector", start=modbus_detector_unit,
                     own_faults=("interlock",)),
    StageEmulator(name="zaber", start=chain_on_pty(ZaberEmulator), chained=True,
                  settings=IDENTITY_CHECKS),
    EnvironmentEmulator(name="modbus-environment", start=modbus_environment_unit),
    FilterWheelEmulator(name="fw102c", start=selector_on_pty(Fw102cEmulator, "positions")),
    MonochromatorEmulator(name="cornerstone", start=selector_on_pty(CornerstoneEmulator)),
)}


def kind_of(name: str, device: Mapping[str, Any]) -> EmulatorKind:
    """The kind of the config's device `name` (its [devices.<name>] table), or a
    SimConfigError listing the kinds sim emulates."""
    protocol = device.get("protocol")
    if protocol not in KINDS:
        raise SimConfigError(f"[devices.{name}] protocol {protocol!r}: no such device kind "
                             f"(kinds: {', '.join(KINDS)})")
    return KINDS[protocol]


def check_faults(name: str, kind: EmulatorKind, faults: Mapping[str, Any]) -> None:
    """Refuse a [sim.faults.<name>] key that only other kinds act on (the kind's own, or any
    kind's common fault keys, pass)."""
    for key in faults:
        if key in KIND_FAULTS and key not in kind.own_faults:
            takers = " or a ".join(f"{k.name} {k.role}" for k in KINDS.values()
                                   if key in k.own_faults)
            raise SimConfigError(f"[sim.faults.{name}] {key}: only a {takers} "
                                 f"{KIND_FAULTS[key]}")


def check_settings(name: str, kind: EmulatorKind, settings: Mapping[str, Any]) -> None:
    """Refuse a [sim.devices.<name>] key the device's kind does not take, or a value the key's
    check refuses, with one SimConfigError naming the key."""
    for key, value in settings.items():
        if key not in kind.settings:
            known = ", ".join(kind.settings) or "none"
            raise SimConfigError(f"[sim.devices.{name}] {key}: the {kind.name} emulator takes "
                                 f"no such key (keys: {known})")
        problem = kind.settings[key](value)
        if problem is not None:
            raise SimConfigError(f"[sim.devices.{name}] {key}: {problem}")


def emulator_groups(chosen: Sequence[str], devices: Mapping[str, Mapping[str, Any]],
                    kinds: Mapping[str, EmulatorKind], line_key: LineKey) -> list[tuple[str, ...]]:
    """The chosen devices as their emulators serve them, in config order: each device alone,
    but the devices of a chained kind on one port or resource together (a daisy chain), the
    first leading; SimConfigError if a chain is only partly chosen (a chain is one line: it is
    emulated whole or not at all). line_key: what a port or resource is known by, so that one
    written two ways is one line."""
    def line(name: str) -> Hashable | None:
        written = line_of(devices[name])
        return None if written is None else line_key(written)

    groups: dict[Any, list[str]] = {}
    for name in chosen:
        kind, on = kinds[name], line(name)
        chained = isinstance(kind, StageEmulator) and kind.chained and on is not None
        groups.setdefault((kind.name, on) if chained else name, []).append(name)
        if chained:
            left_out = [other for other in devices if other not in chosen
                        and kinds[other] is kind and line(other) == on]
            if left_out:
                raise SimConfigError(f"{name} and {left_out[0]} are one {kind.name} chain "
                                     f"({on}): emulate both or neither")
    return [tuple(names) for names in groups.values()]
