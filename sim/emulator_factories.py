"""Starting one device's emulator from its config tables: what a kind's factory is handed
(`EmulatedDevice`, and a detector's `Light`), and the factories of the kinds sim serves.

sim.device_kinds points each kind at one of these. A factory builds the emulator, hands it
to `serve` (a pty or socket of its own) or `join_bus` (a Modbus unit on the server of its bus
or TCP endpoint), and reports each emulated stage's position and target through `stage`;
a detector's factory returns the detector model whose noise a resume continues.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from sim.devices.faults import FaultSpec, InterlockInput
from sim.devices.modbus_detector import ModbusDetectorEmulator
from sim.devices.modbus_server import EmulatedUnit
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import PhotodiodeModel, PowerSource
from sim.devices.pty_server import PtyDevice


@dataclass(frozen=True)
class EmulatedDevice:
    """One device of a config as its factory sees it: its [devices.<name>] table, the
    [axes.<role>] tables of the roles it drives, the bench's clock, its seed, faults, serial
    number and interlock input (its faults open it), what the emulator pretends to be (its
    [sim.devices.<name>] table, `settings`, checked against its kind's `settings` choices),
    and where to serve it and report its stages: `serve` starts a PtyDevice on a pty of its
    own (its `protocol` names it in `gonio emulate`'s output), `join_bus` puts a Modbus unit
    on the one server of its bus or TCP endpoint, `stage(role, position, target)` says where
    an emulated stage is and where it was told to go."""

    name: str
    table: Mapping[str, Any]
    axes: Mapping[str, Mapping[str, Any]]
    clock: VirtualClock
    seed: int
    faults: FaultSpec | None
    serial: str
    interlock: InterlockInput | None
    settings: Mapping[str, Any]
    serve: Callable[[PtyDevice], None]
    join_bus: Callable[[EmulatedUnit], None]
    stage: Callable[[str, Callable[[], float], Callable[[], float]], None]


@dataclass(frozen=True)
class Light:
    """What lights a detector emulator: the bench's PowerSource, the [sim.detector] table, the
    light's wavelength, and the commanded positions that key the noise (`place`)."""

    source: PowerSource
    detector: Mapping[str, Any] | None
    wavelength_nm: float
    place: Callable[[], tuple[float, ...]]


StageFactory = Callable[[EmulatedDevice], None]
DetectorFactory = Callable[[EmulatedDevice, Light], PhotodiodeModel]


def home_deg(limits: Any) -> float:
    """Where an emulated stage powers up: 0, or the nearest limit if 0 is outside travel."""
    return min(max(0.0, float(limits[0])), float(limits[1]))


def _axis_number(axis: Mapping[str, Any]) -> int:
    return axis.get("axis", 1)


def controller_on_pty(emulator: type, device_keys: tuple[str, ...] = (),
                      interlock_arg: str | None = None) -> StageFactory:
    """A multi-axis controller served on a pty of its own, built as `emulator(clock,
    {axis number: {limits_deg, speed_deg_s, accel_deg_s2, position_deg}}, faults, seed,
    **device_keys the [devices] table gives, **its [sim.devices.<name>] settings)` (a Zaber
    product's `device_id`, `firmware`, `alerts`) with each axis's TrapezoidAxis at
    `.axes[number].motion` (the ESP emulator's shape); interlock_arg: the constructor argument
    that takes its interlock input (the ESP's `estop`), if it has one."""
    def start(device: EmulatedDevice) -> None:
        tables = {_axis_number(ax): {"limits_deg": tuple(ax["limits_deg"]),
                                     "speed_deg_s": ax["speed_deg_s"],
                                     "accel_deg_s2": ax["accel_deg_s2"],
                                     "position_deg": home_deg(ax["limits_deg"])}
                  for ax in device.axes.values()}
        given = {key: device.table[key] for key in device_keys if key in device.table}
        if interlock_arg is not None:
            given[interlock_arg] = device.interlock
        emu = emulator(device.clock, tables, device.faults, device.seed, **given,
                       **device.settings)
        device.serve(emu)
        for role, ax in device.axes.items():
            motion = emu.axes[_axis_number(ax)].motion
            device.stage(role, motion.position, motion.target)
    return start


def meter_on_pty(emulator: type) -> DetectorFactory:
    """A meter served on a pty of its own, built as `emulator(source, faults=, seed=,
    detector=, light_wavelength_nm=, place=, **its [sim.devices.<name>] settings)` (the
    PM100's console `model` and `sensor` head) with its model at `.photodiode`."""
    def start(device: EmulatedDevice, light: Light) -> PhotodiodeModel:
        emu = emulator(light.source, faults=device.faults, seed=device.seed,
                       detector=light.detector, light_wavelength_nm=light.wavelength_nm,
                       place=light.place, **device.settings)
        device.serve(emu)
        return emu.photodiode
    return start


def modbus_stage_units(device: EmulatedDevice) -> None:
    """A Modbus stepper drive per axis, as its register map describes it, on its bus."""
    for role, ax in device.axes.items():
        unit = ModbusStageEmulator(device.clock, device.table["register_map"],
                                   tuple(ax["limits_deg"]), ax["speed_deg_s"],
                                   ax["accel_deg_s2"], device.faults, home_deg(ax["limits_deg"]),
                                   serial=device.serial, interlock=device.interlock)
        device.join_bus(unit)
        device.stage(role, unit.axis.position, unit.axis.target)


def modbus_detector_unit(device: EmulatedDevice, light: Light) -> PhotodiodeModel:
    """A Modbus photodiode amplifier, as its register map describes it, on its bus."""
    unit = ModbusDetectorEmulator(light.source, device.table["register_map"], device.faults,
                                  device.seed, light.detector, light.wavelength_nm,
                                  serial=device.serial, place=light.place,
                                  interlock=device.interlock)
    device.join_bus(unit)
    return unit.model
