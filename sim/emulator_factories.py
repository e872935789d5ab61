"""Starting one device's emulator from its config tables: what a kind's factory is handed
(`EmulatedDevice`, a detector's `Light`, an environment sensor's room), and the factories of
the kinds sim serves (stages, detectors, environment sensors, wavelength selectors).

sim.device_kinds points each kind at one of these. A factory builds the emulator, hands it
to `serve` (a pty or socket of its own, shared with the device's `mates` on a daisy chain) or
`join_bus` (a Modbus unit on the server of its bus or TCP endpoint), and reports each emulated
stage's position and target through `stage`; a detector's factory returns the detector model
whose noise a resume continues.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from sim.devices.faults import FaultSpec, InterlockInput
from sim.devices.modbus_detector import ModbusDetectorEmulator
from sim.devices.modbus_environment import ModbusEnvironmentEmulator
from sim.devices.modbus_server import EmulatedUnit
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import PhotodiodeModel, PowerSource, SimConfigError
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
    an emulated stage is and where it was told to go. `mates`: the later devices of a daisy
    chain this one leads (the same port or resource), which its emulator serves with it."""

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
    mates: tuple[EmulatedDevice, ...] = ()


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
#: the room an environment sensor reads: (deg C, relative humidity 0..1) now
RoomNow = Callable[[], tuple[float, float]]
EnvironmentFactory = Callable[[EmulatedDevice, RoomNow], None]
SelectorFactory = Callable[[EmulatedDevice], None]


def home_deg(limits: Any) -> float:
    """Where an emulated stage powers up: 0, or the nearest limit if 0 is outside travel."""
    return min(max(0.0, float(limits[0])), float(limits[1]))


def _axis_number(axis: Mapping[str, Any]) -> int:
    return axis.get("axis", 1)


def _axis_tables(device: EmulatedDevice) -> dict[int, dict[str, Any]]:
    """{axis number: {limits_deg, speed_deg_s, accel_deg_s2, position_deg}} of a device's
    axes, each powered up at home_deg."""
    return {_axis_number(ax): {"limits_deg": tuple(ax["limits_deg"]),
                               "speed_deg_s": ax["speed_deg_s"],
                               "accel_deg_s2": ax["accel_deg_s2"],
                               "position_deg": home_deg(ax["limits_deg"])}
            for ax in device.axes.values()}


def _report_stages(device: EmulatedDevice, emulated_axes: Mapping[Any, Any],
                   address: int | None = None) -> None:
    """Tell the bench where each of the device's roles is: the TrapezoidAxis at
    `emulated_axes[axis number].motion`, or on a chain `[address, axis number]`."""
    for role, ax in device.axes.items():
        number = _axis_number(ax)
        motion = emulated_axes[number if address is None else (address, number)].motion
        device.stage(role, motion.position, motion.target)


def controller_on_pty(emulator: type, interlock_arg: str | None = None) -> StageFactory:
    """A multi-axis controller served on a pty of its own, built as `emulator(clock,
    {axis number: {limits_deg, speed_deg_s, accel_deg_s2, position_deg}}, faults, seed,
    **its [sim.devices.<name>] settings)` with each axis's TrapezoidAxis at
    `.axes[number].motion` (the ESP emulator's shape); interlock_arg: the constructor argument
    that takes its interlock input (the ESP's `estop`), if it has one."""
    def start(device: EmulatedDevice) -> None:
        given = {} if interlock_arg is None else {interlock_arg: device.interlock}
        emu = emulator(device.clock, _axis_tables(device), device.faults, device.seed, **given,
                       **device.settings)
        device.serve(emu)
        _report_stages(device, emu.axes)
    return start


def chain_on_pty(emulator: type, address: str = "address") -> StageFactory:
    """A daisy chain (a device and its mates, each at its `address` in the [devices] table,
    default 1) served by one emulator on one pty, built as `emulator(clock, {(address, axis
    number): table}, faults, seed, **[sim.devices] settings)` with each axis's TrapezoidAxis
    at `.axes[address, number].motion` (the Zaber emulator's shape). The chain is one line
    with the leading device's faults and one product (its devices' [sim.devices] tables the
    same where given), each device at an address of its own: else one SimConfigError naming
    two devices."""
    def start(device: EmulatedDevice) -> None:
        chain = (device, *device.mates)
        settings = _chain_product(chain, address)
        tables = {(dev.table.get(address, 1), number): table
                  for dev in chain for number, table in _axis_tables(dev).items()}
        emu = emulator(device.clock, tables, device.faults, device.seed, **settings)
        device.serve(emu)
        for dev in chain:
            _report_stages(dev, emu.axes, dev.table.get(address, 1))
    return start


def line_of(table: Mapping[str, Any]) -> str | None:
    """The port or resource a [devices] table names (None: neither, a networked device)."""
    return table.get("port", table.get("resource"))


def _chain_product(chain: tuple[EmulatedDevice, ...], address: str) -> Mapping[str, Any]:
    """What a chain's devices are (the [sim.devices] table given, or none: the emulator's
    defaults); SimConfigError for two devices at one address, faults given for a device but
    the first, or two different products."""
    def clash(key: str, dev: EmulatedDevice, first: EmulatedDevice, why: str) -> SimConfigError:
        return SimConfigError(f"{key}: {dev.name} is on one chain with {first.name} "
                              f"({line_of(first.table)}): {why}")

    at: dict[Any, EmulatedDevice] = {}
    for dev in chain:
        first = at.setdefault(dev.table.get(address, 1), dev)
        if first is not dev:
            raise clash(f"[devices.{dev.name}] {address}", dev, first, "at the same address")
        if dev.faults is not None and dev is not chain[0]:
            raise clash(f"[sim.faults.{dev.name}]", dev, chain[0], "one line, whose faults "
                        f"are [sim.faults.{chain[0].name}]")
    products = [dev for dev in chain if dev.settings]
    for dev in products[1:]:
        if dev.settings != products[0].settings:
            raise clash(f"[sim.devices.{dev.name}]", dev, products[0], "one emulated product, "
                        f"unlike [sim.devices.{products[0].name}]")
    return products[0].settings if products else {}


def meter_on_pty(emulator: type) -> DetectorFactory:
    """A meter served on a pty of its own, built as `emulator(source, faults=, seed=,
    detector=, light_wavelength_nm=, place=, clock=, **its [sim.devices.<name>] settings)` (the
    PM100's console `model` and `sensor` head) with its model at `.photodiode`."""
    def start(device: EmulatedDevice, light: Light) -> PhotodiodeModel:
        emu = emulator(light.source, faults=device.faults, seed=device.seed,
                       detector=light.detector, light_wavelength_nm=light.wavelength_nm,
                       place=light.place, clock=device.clock, **device.settings)
        device.serve(emu)
        return emu.photodiode
    return start


def selector_on_pty(emulator: type, *table_keys: str) -> SelectorFactory:
    """A filter wheel or monochromator served on a pty of its own, built as `emulator(clock,
    faults=, seed=, **the keys `table_keys` of its [devices] table that it has (a wheel's
    `positions`), **its [sim.devices.<name>] settings)`."""
    def start(device: EmulatedDevice) -> None:
        given = {key: device.table[key] for key in table_keys if key in device.table}
        device.serve(emulator(device.clock, faults=device.faults, seed=device.seed, **given,
                              **device.settings))
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
                                  interlock=device.interlock, clock=device.clock)
    device.join_bus(unit)
    return unit.model


def modbus_environment_unit(device: EmulatedDevice, room: RoomNow) -> None:
    """A Modbus temperature and humidity transmitter, as its register map describes it, on its
    bus, reading the bench's room."""
    device.join_bus(ModbusEnvironmentEmulator(room, device.table["register_map"], device.faults,
                                              serial=device.serial))
