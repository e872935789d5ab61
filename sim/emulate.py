"""Start every emulated device of an instrument config, and the optical bench behind them.

`start(config)` takes the config as a plain dict (the parsed TOML) and serves each device
on a real pty (serial, Modbus RTU) or TCP socket (Modbus TCP, and a line device whose
`resource` is a TCPIP SOCKET one; on loopback unless `bind` names another address: the
config's hosts are the real devices', never listen addresses), with motion on one
VirtualClock, the detectors' light from the bench at the stages' positions and the
environment sensors' air from its room ([sim.room], drifting on the run's clock). It returns
the endpoints, so a caller can point the config's ports at them. `devices` limits it to
some of the devices (hardware in the loop); then `positions()` must say where the real
stages are.

A seeded emulated run does not depend on the machine's load or on a resume: the detectors'
noise is keyed on the seed, the device, the commanded positions (the emulated stages'
targets), the range setting and the visit count (sim.devices.photodiode), and the source
drifts (and the faults' interlocks open) on the run's clock (`EmulatedBench.run_time`): the
bench's VirtualClock from the run's start, on which moves, settling and readings take their
time at every time scale (a resumed run's clock goes on from where its last session ended:
`begin_run`), or, for a run with real devices in the loop, the caller's `run_time` (wall
seconds since the run started). A resumed run passes its stored readings as `visited` so the
visit counts go on. A request a client re-sends after its timeout is a new measurement
(docs/bench.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from sim.bench import build_power_source
from sim.bench.room import build_room
from sim.bench.tables import Progress, TablesPrepared
from sim.device_kinds import (
    DetectorEmulator,
    EmulatorKind,
    EnvironmentEmulator,
    LineKey,
    SelectorEmulator,
    StageEmulator,
    check_faults,
    check_settings,
    emulator_groups,
    kind_of,
)
from sim.devices.faults import FaultInjector, FaultSpec, InterlockInput
from sim.devices.modbus_server import ModbusEmulatorServer
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import SimConfigError
from sim.devices.pty_server import LOOPBACK
from sim.emulator_factories import EmulatedDevice, Light, RoomNow
from sim.served_resources import serve_resource

SIM_KEYS = ("time_scale", "seed", "source", "sample", "samples", "aperture", "alignment", "stray",
            "room", "detector", "faults", "devices")
ROLES = ("sample", "arm", "azimuth", "elevation")
#: A reading taken before this bench started: its commanded positions ({role: deg}) and its
#: range setting (full scale in W; None = autorange).
Visit = tuple[Mapping[str, float], float | None]


@dataclass(frozen=True)
class Endpoint:
    """Where one emulated device listens: a pty path, 127.0.0.1:PORT (Modbus TCP), or the VISA
    resource string of what it serves for a device the config gives by `resource`."""

    name: str
    protocol: str
    endpoint: str

    @property
    def line(self) -> str:
        """`NAME PROTOCOL ENDPOINT`, as `gonio emulate` prints it."""
        return f"{self.name} {self.protocol} {self.endpoint}"


@dataclass
class EmulatedBench:
    """Running emulators: endpoints by device name, the shared clock, what to stop."""

    clock: VirtualClock
    endpoints: dict[str, Endpoint] = field(default_factory=dict)
    emulators: dict[str, Any] = field(default_factory=dict)
    injectors: dict[str, list[FaultInjector]] = field(default_factory=dict)
    meters: list[Any] = field(default_factory=list)  # the emulated detectors' models
    #: what start's prepare built (None: no schedule given)
    tables: TablesPrepared | None = None
    _stops: list[Callable[[], None]] = field(default_factory=list)
    _origin: float = 0.0  # the clock's reading at the run's time 0

    def begin_run(self, at_s: float) -> None:
        """The run's clock (run_time) reads at_s now: 0 for a new run, where the last session
        ended for a resumed one."""
        self._origin = self.clock.run_time() - at_s

    def run_time(self) -> float:
        """Seconds of the run in the devices' modelled time (VirtualClock.run_time: the clock
        of t_s of a run whose devices are all emulated, the same at any load)."""
        return self.clock.run_time() - self._origin

    def command_time(self) -> float:
        """run_time as a device handles a command: on an instant clock the motions begun are
        still under way (VirtualClock.start_time), so a device that looks at the time (an
        interlock input) does not run axes started together one after the other."""
        return self.clock.run_start_time() - self._origin

    def wait_s(self, seconds: float) -> float:
        """Real seconds a wait of `seconds` on the run's clock takes (settling, dwell, a
        suspension's recheck; VirtualClock.wait)."""
        return self.clock.wait(seconds)

    def tables_record(self) -> dict[str, float] | None:
        """The tables prepared before the first reading, with the planes built inside readings
        since (a position the schedule did not foresee), for the session's record."""
        return None if self.tables is None else self.tables.record()

    def fault_counts(self) -> dict[str, dict[str, int]]:
        """Faults injected so far, by device and kind (devices with faults configured)."""
        out = {}
        for name, injectors in self.injectors.items():
            totals: dict[str, int] = {}
            for inj in injectors:
                for kind, n in inj.counts.items():
                    totals[kind] = totals.get(kind, 0) + n
            out[name] = totals
        return out

    def request_counts(self) -> dict[str, int]:
        """Requests served so far by each pty-served device (ESP, PM100)."""
        return {name: emu.server.requests for name, emu in self.emulators.items()
                if hasattr(emu, "server")}

    def forget(self, visit: Visit) -> None:
        """A reading taken at `visit` was thrown away by the client: it does not count as a
        visit there (a re-measured reading gets the noise an undisturbed run gives it)."""
        where, range_w = visit
        for meter in self.meters:
            meter.forget(_place(where), range_w)

    def stop(self) -> None:
        """Stop every emulator (idempotent)."""
        while self._stops:
            self._stops.pop()()

    def __enter__(self) -> EmulatedBench:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


#: The fastest finite time scale: the emulated ESP refuses a motion that would end past its
#: clock's horizon (sim.devices.esp_commands.HORIZON_S, 3.6e12 virtual s), which a clock a
#: fuzzed 8e13 times faster than real time passed within a second of starting.
MAX_TIME_SCALE = 1e6


def time_scale_of(sim: Mapping[str, Any]) -> float:
    """The [sim] time_scale: virtual seconds per real second, real time (1) or accelerated
    (1 to MAX_TIME_SCALE, or "inf": moves complete at once). Slow motion is refused: a fuzzed
    8e-244 once made a one-degree move outlast the universe."""
    value = sim.get("time_scale", 1.0)
    if value == "inf":
        return math.inf
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or not 1 <= value <= MAX_TIME_SCALE:
        raise SimConfigError(f"[sim] time_scale: must be a number >= 1 (1 = real time) and "
                             f'<= {MAX_TIME_SCALE:.0f}, or "inf" (instant), got {value!r}')
    return float(value)


def _kinds(config: Mapping[str, Any]) -> dict[str, EmulatorKind]:
    """Every device's kind, by device name (an unknown protocol is an error, never skipped)."""
    devices = config.get("devices", {})
    return {name: kind_of(name, dev) for name, dev in devices.items()}


def _sim_table(config: Mapping[str, Any], kinds: Mapping[str, EmulatorKind]) -> dict[str, Any]:
    sim = config.get("sim", {})
    if not isinstance(sim, Mapping):
        raise SimConfigError("[sim]: must be a table")
    unknown = sorted(set(sim) - set(SIM_KEYS))
    if unknown:
        raise SimConfigError(f"[sim]: unknown key {unknown[0]!r}; known: {', '.join(SIM_KEYS)}")
    seed = sim.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise SimConfigError(f"[sim] seed: must be an integer, got {seed!r}")
    for key, check in (("faults", check_faults), ("devices", check_settings)):
        for device, table in _device_tables(config, sim, key).items():
            check(device, kinds[device], table)
    return dict(sim)


def _device_tables(config: Mapping[str, Any], sim: Mapping[str, Any], key: str
                   ) -> Mapping[str, Mapping[str, Any]]:
    """[sim.<key>]: a table of tables, one per device of [devices] (SimConfigError otherwise)."""
    tables = sim.get(key, {})
    if not isinstance(tables, Mapping):
        raise SimConfigError(f"[sim.{key}]: must be a table of device tables, got {tables!r}")
    for device, table in tables.items():
        if device not in config.get("devices", {}):
            raise SimConfigError(f"[sim.{key}.{device}]: no device {device!r} under [devices]")
        if not isinstance(table, Mapping):
            raise SimConfigError(f"[sim.{key}.{device}]: must be a table, got {table!r}")
    return tables


def _modbus_group(dev: Mapping[str, Any], line_key: LineKey) -> tuple[str, Hashable]:
    """Devices sharing a bus (its port by line_key) or a TCP endpoint share one emulated
    server."""
    if dev["transport"] == "tcp":
        return "tcp", f"{dev['host']}:{dev.get('tcp_port', 502)}"
    return "rtu", line_key(str(dev["port"]))


class _Builder:
    """Creates the emulators of one config, stages first, then the bench, the detectors and
    the environment sensors."""

    def __init__(self, config: Mapping[str, Any], sim: dict[str, Any], chosen: list[str],
                 kinds: Mapping[str, EmulatorKind], bench: EmulatedBench, bind: str,
                 run_time: Callable[[], float], command_time: Callable[[], float],
                 line_key: LineKey):
        self.config, self.sim, self.bench, self.bind = config, sim, bench, bind
        self.run_time, self.command_time = run_time, command_time
        self.line_key = line_key
        self.devices: Mapping[str, Mapping[str, Any]] = config["devices"]
        self.chosen, self.kinds = chosen, kinds
        self.seed = sim.get("seed", 0)
        self.readers: dict[str, Callable[[], float]] = {}  # where each stage is
        self.targets: dict[str, Callable[[], float]] = {}  # where it was told to go
        self.modbus: dict[tuple[str, Hashable], dict[int, tuple[str, Any]]] = {}

    def _seed(self, name: str) -> int:
        return self.seed + list(self.devices).index(name)

    def _serial(self, name: str) -> str:
        """A Modbus unit's serial number: one per device and seed (another seed, other
        hardware)."""
        return f"SIM{self._seed(name):05d}"

    def _faults(self, name: str) -> FaultSpec | None:
        table = self.sim.get("faults", {}).get(name)
        if table is None:
            return None
        return FaultSpec.from_dict({"seed": self._seed(name), **table}, name)

    def _interlock(self, name: str) -> InterlockInput | None:
        """The device's interlock input, if its faults open it (on the run's clock)."""
        spec = self._faults(name)
        if spec is None or spec.interlock is None:
            return None
        return InterlockInput(spec.interlock, self.command_time)

    def _roles(self, name: str) -> dict[str, Mapping[str, Any]]:
        return {role: ax for role, ax in self.config["axes"].items() if ax["device"] == name}

    def _device(self, name: str, mates: tuple[str, ...] = ()) -> EmulatedDevice:
        """What the device's kind starts its emulator from (with the `mates` on its chain),
        and where it serves it."""
        def stage(role: str, position: Callable[[], float], target: Callable[[], float]) -> None:
            self.readers[role], self.targets[role] = position, target

        return EmulatedDevice(name, self.devices[name], self._roles(name), self.bench.clock,
                              self._seed(name), self._faults(name), self._serial(name),
                              self._interlock(name), self.sim.get("devices", {}).get(name, {}),
                              serve=lambda emu: _serve(self.bench, (name, *mates), emu,
                                                       self.devices[name], self.bind),
                              join_bus=lambda unit: self._add_modbus(name, unit), stage=stage,
                              mates=tuple(self._device(mate) for mate in mates))

    def _add_modbus(self, name: str, unit: Any) -> None:
        dev = self.devices[name]
        units = self.modbus.setdefault(_modbus_group(dev, self.line_key), {})
        units[dev.get("unit", 1)] = (name, unit)
        if unit.faults is not None:
            self.bench.injectors.setdefault(name, []).append(unit.faults)

    def stages(self) -> None:
        """Emulators of the chosen stage devices (served on ptys now, a chain's devices by
        one, Modbus units collected)."""
        for name, *mates in emulator_groups(self.chosen, self.devices, self.kinds,
                                            self.line_key):
            kind = self.kinds[name]
            if isinstance(kind, StageEmulator):
                kind.start(self._device(name, tuple(mates)))

    def detectors(self, source: Any, place: Callable[[], tuple[float, ...]],
                  visited: list[tuple[tuple[float, ...], float | None]]) -> None:
        """Emulators of the chosen detectors, lit by `source` (the bench's PowerSource), their
        noise keyed on `place()` (the commanded positions) and counting `visited` as taken."""
        light = Light(source, self.sim.get("detector"), source.bench.source.wavelength_nm, place)
        for name in self.chosen:
            kind = self.kinds[name]
            if isinstance(kind, DetectorEmulator):
                meter = kind.start(self._device(name), light)
                self.bench.meters.append(meter)
                for where, range_w in visited:
                    meter.visited(where, range_w)

    def environment_sensors(self, room: RoomNow) -> None:
        """Emulators of the chosen environment sensors, reading `room()`."""
        for name in self.chosen:
            kind = self.kinds[name]
            if isinstance(kind, EnvironmentEmulator):
                kind.start(self._device(name), room)

    def wavelength_selectors(self) -> None:
        """Emulators of the chosen filter wheels and monochromators."""
        for name in self.chosen:
            kind = self.kinds[name]
            if isinstance(kind, SelectorEmulator):
                kind.start(self._device(name))

    def serve_modbus(self) -> None:
        """One Modbus server per bus or TCP endpoint, with all its collected units."""
        for (transport, _), units in self.modbus.items():
            first = self.devices[next(iter(units.values()))[0]]  # a bus has one baud rate
            server = ModbusEmulatorServer(transport, {u: emu for u, (_, emu) in units.items()},
                                          baudrate=int(first.get("baudrate", 19200)),
                                          host=self.bind)
            endpoint = server.start()
            self.bench._stops.append(server.stop)
            for name, _ in units.values():
                self.bench.emulators[name] = server
                self.bench.endpoints[name] = Endpoint(name, server.protocol, endpoint)


def start(config: Mapping[str, Any], devices: Iterable[str] | None = None,
          positions: Callable[[], Mapping[str, float]] | None = None,
          sample: Mapping[str, Any] | None = None, bind: str = LOOPBACK,
          run_time: Callable[[], float] | None = None, visited: Iterable[Visit] = (),
          line_key: LineKey = str, upcoming: Iterable[Mapping[str, float]] | None = None,
          progress: Progress | None = None) -> EmulatedBench:
    """Serve the config's devices (all, or those named) and return the running bench, ready:
    with a detector among them, the model's kernels and what a reading where the stages stand
    needs (sim.bench.scene.Bench.warm_up) are built before it is served.

    positions: where the stages that are not emulated are ({role: deg}); needed when a
    detector is emulated but some stage is real. The bench is the config's [optics] with the
    plan's [sample] table (`sample`, if a plan is known) and the [sim] truth (sim.bench.config).
    bind: the address Modbus TCP emulators listen on (loopback by default). run_time: the
    run's clock, seconds since it started, that the source drifts and the faults' interlocks
    open on (default: the bench's own, `EmulatedBench.run_time`, 0 when the bench is ready);
    visited: the readings the run took before this bench (a resume), see Visit. line_key:
    what a port or resource is known by, so that a chain's or a bus's port written two ways
    (a device file and a symlink to it) is one line (gonio hands it its ports' hold's key);
    by default as written. upcoming: the commanded positions ({role: deg}) of the readings
    to come (a plan's schedule): with a sample whose multiple scattering is tabulated, the
    tables they need are built before serving instead (sim.bench.scene.Bench.prepare, walks
    told to `progress`).
    """
    kinds = _kinds(config)
    sim = _sim_table(config, kinds)
    all_devices = config["devices"]
    chosen = list(all_devices) if devices is None else list(devices)
    for name in chosen:
        if name not in all_devices:
            raise SimConfigError(f"no device {name!r} to emulate (devices: "
                                 f"{', '.join(all_devices)})")
    bench = EmulatedBench(VirtualClock(time_scale_of(sim)))
    # the source drifts (and the faults' interlocks open) on the clock of the run store's t_s:
    # drift normalisation needs both
    build = _Builder(config, sim, chosen, kinds, bench, bind, run_time or bench.run_time,
                     run_time or bench.command_time, line_key)
    try:
        build.stages()
        build.wavelength_selectors()
        missing = set(config["axes"]) - set(build.readers)
        detectors = [n for n in chosen if isinstance(kinds[n], DetectorEmulator)]
        if missing and positions is None and detectors:
            raise SimConfigError(f"emulating {detectors[0]!r} without the stages "
                                 f"{', '.join(sorted(missing))} needs their positions")

        def read(stages: dict[str, Callable[[], float]]) -> dict[str, float]:
            """Emulated stages read directly, real ones from the caller's positions()."""
            real = dict(positions()) if missing else {}
            return {role: stages[role]() if role in stages else float(real.get(role, 0.0))
                    for role in ROLES}

        source = build_power_source(sim, lambda: read(build.readers), build.run_time,
                                    optics=config.get("optics"), sample=sample)
        if detectors and upcoming is not None and source.bench.sample.tabulated:
            # no reading walks a table inside its reply (its evaluation compiles the kernels)
            bench.tables = source.bench.prepare(upcoming, progress)
        elif detectors:  # the first reading must not stall past a driver's timeout: the model
            # compiled and what a reading where the stages stand needs built, before serving
            source.bench.warm_up(read(build.readers))
        build.detectors(source, lambda: _place(read(build.targets)),
                        [(_place(where), range_w) for where, range_w in visited])
        build.environment_sensors(build_room(sim, build.run_time).now)
        build.serve_modbus()
        bench.begin_run(0.0)
    except BaseException:
        bench.stop()
        raise
    return bench


def _place(positions: Mapping[str, float]) -> tuple[float, ...]:
    """A reading's place for the noise key: the positions of every role, in ROLES order."""
    return tuple(float(positions.get(role, 0.0)) for role in ROLES)


def _serve(bench: EmulatedBench, names: tuple[str, ...], emu: Any, table: Mapping[str, Any],
           bind: str) -> None:
    """Serve a line emulator of the devices `names` (one, or a chain's) on a pty, or, for a
    device given by a VISA resource, on the link the resource names (sim.served_resources);
    its endpoint is then that resource string, every device's."""
    if emu.server.faults.spec.active:
        bench.injectors.setdefault(names[0], []).append(emu.server.faults)
    resource = table.get("resource")
    endpoint = emu.start() if resource is None else serve_resource(emu, resource, bind)
    bench._stops.append(emu.stop)
    for name in names:
        bench.emulators[name] = emu
        bench.endpoints[name] = Endpoint(name, emu.protocol, endpoint)
