"""The one gonio module that imports `sim`: start emulated devices and point a config at them.

Used by `gonio scan --sim` (all devices, or the named devices/roles: hardware in the loop)
and by `gonio emulate` (serve a config's devices for another process to use).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.port_identity import port_key
from gonio.config import InstrumentConfig, parse_config
from gonio.errors import ConfigError
from gonio.events import Moved, ReadingDiscarded, Stopping
from gonio.plan import AUTO_RANGE, Plan, Schedule
from gonio.progress import TablesProgress
from gonio.run_clock import RunClock
from sim.bench import Bench, build_bench, tables
from sim.bench.config import read_table
from sim.bench.tables import TablesEstimate
from sim.devices.pty_server import LOOPBACK
from sim.emulate import EmulatedBench, Visit, start, time_scale_of


@dataclass
class Simulation:
    """A running emulation: the config pointed at it, its time scale, what is emulated.

    positions: the dict the emulated detector reads real stages' positions from (the
    hardware-in-the-loop feed, `telemetry`, keeps it current); clock: the run's clock when
    every device is emulated (the bench's virtual clock), None with real devices in the loop
    (the wall clock).
    """

    config: InstrumentConfig
    time_scale: float
    devices: list[str]
    positions: dict[str, float]
    bench: EmulatedBench
    clock: RunClock | None = None

    def session_start(self) -> dict[str, Any]:
        """What the session's record starts with: the multiple-scattering tables built before
        the first move (`ms_tables`, known then, so a session killed outright keeps it)."""
        tables = self.bench.tables_record()
        return {} if tables is None else {"ms_tables": tables}

    def telemetry(self, event: Any) -> None:
        """The emulation's subscriber to the engine's events: where the (real) stages are
        before each reading, the readings thrown away (no visits: sim.emulate), and what the
        emulators did in the session (faults injected, requests served, the tables record's
        planes built inside readings, and on the virtual clock the run's time at the end,
        `clock_end_s`, where a resume goes on from)."""
        if isinstance(event, Moved):
            self.positions.update(event.positions)
        elif isinstance(event, ReadingDiscarded):
            self.bench.forget(visit(event.row, self.config.axes))
        elif isinstance(event, Stopping):
            event.session.update(faults_injected=self.bench.fault_counts(),
                                 requests_served=self.bench.request_counts())
            if self.clock is not None:
                event.session["clock_end_s"] = self.clock.now()
            tables = self.bench.tables_record()
            if tables is not None:
                event.session["ms_tables"] = tables


def visit(row: np.void, roles: Iterable[str]) -> Visit:
    """A scheduled reading as the emulated detector counts it: the commanded positions of
    `roles` and the range setting (None = autorange)."""
    return ({role: float(row[f"{role}_deg"]) for role in roles},
            None if row["range_w"] == AUTO_RANGE else float(row["range_w"]))


def resolve_devices(cfg: InstrumentConfig, names: list[str] | None) -> list[str]:
    """Device names for `--sim [NAMES]`: None = all; a name may be a device or a role
    (sample, arm, azimuth, elevation, detector, environment)."""
    if names is None:
        return list(cfg.devices)
    out = []
    for name in names:
        if name in cfg.devices:
            dev = name
        elif name in cfg.axes:
            dev = cfg.axes[name].device
        elif name == "detector":
            dev = cfg.detector.device
        elif name == "environment" and cfg.environment is not None:
            dev = cfg.environment
        else:
            roles = ", ".join([*cfg.axes, "detector", *(["environment"] if cfg.environment
                                                       else [])])
            raise ConfigError(f"--sim {name}: no such device or role (devices: "
                              f"{', '.join(cfg.devices)}; roles: {roles})")
        if dev not in out:
            out.append(dev)
    return out


def point_at(cfg: InstrumentConfig, endpoints: dict[str, str]) -> InstrumentConfig:
    """A copy of the config whose named devices' ports / hosts are the given endpoints."""
    raw = copy.deepcopy(cfg.raw)
    for name, endpoint in endpoints.items():
        raw["devices"][name].update(cfg.devices[name].endpoint_values(endpoint))
    return parse_config(raw, cfg.path)


def _start(cfg: InstrumentConfig, devices: list[str], positions: dict[str, float],
           sample: dict | None = None, bind: str = LOOPBACK, t0_epoch: float | None = None,
           visited: Iterable[Visit] = (), upcoming: np.ndarray | None = None,
           progress: bool | None = None) -> EmulatedBench:
    """The emulators of `devices`; with a real device among the config's, the source drifts
    in wall seconds since t0_epoch (the engine's clock then), else on the bench's own."""
    wall = None if t0_epoch is None or set(devices) == set(cfg.devices) else (
        lambda: time.time() - t0_epoch)
    try:
        return start(cfg.raw, devices, lambda: positions, sample, bind, wall, visited,
                     line_key=port_key, upcoming=_positions(upcoming, cfg.axes),
                     progress=_tables_progress(cfg, sample, progress))
    except ValueError as exc:
        raise ConfigError(f"{cfg.path or 'config'}: {exc}") from None


def _positions(rows: np.ndarray | None, roles: Iterable[str]) -> list[dict[str, float]] | None:
    """Schedule rows' commanded positions by role (None: no schedule)."""
    return None if rows is None else [visit(row, roles)[0] for row in rows]


def _tables_progress(cfg: InstrumentConfig, sample: dict | None, progress: bool | None
                     ) -> TablesProgress:
    """The table building's progress line, labelled with the walks of the sample the plan's
    [sample] mounts (its validated [sim.samples.<id>] or [sim.sample]: SimConfigError if
    bad): shown unless progress is False (--no-progress), on a terminal or not (minutes of
    silence before a scan's first move read as a hang)."""
    walks = read_table(cfg.sim, "sample", sample)["ms_walks"]
    return TablesProgress(int(walks), disable=progress is False)


@contextmanager
def simulation(cfg: InstrumentConfig, names: list[str] | None = None,
               sample: dict | None = None, t0_epoch: float | None = None,
               visited: Iterable[Visit] = (), upcoming: np.ndarray | None = None,
               progress: bool | None = None, clock_start_s: float = 0.0
               ) -> Iterator[Simulation]:
    """Run the emulators of a config for the duration of a `with` block; `sample` is the
    plan's [sample] table (the emulated sample's kind and index unless [sim] states them);
    t0_epoch the run's start and visited its stored readings (sim.emulate.start); upcoming
    the schedule rows still to measure, whose multiple-scattering tables are built first
    (progress: as the scan's bar, False hides it). With every device emulated the run's
    clock is the bench's virtual clock, reading clock_start_s as the block begins (a
    resume: where the run's last session ended)."""
    devices = resolve_devices(cfg, names)
    positions: dict[str, float] = {}
    bench = _start(cfg, devices, positions, sample, t0_epoch=t0_epoch, visited=visited,
                   upcoming=upcoming, progress=progress)
    try:
        pointed = point_at(cfg, {n: e.endpoint for n, e in bench.endpoints.items()})
        stages_emulated = all(ax.device in devices for ax in cfg.axes.values())
        scale = emulated_time_scale(cfg) if stages_emulated else 1.0
        clock = None
        if set(devices) == set(cfg.devices):
            bench.begin_run(clock_start_s)
            clock = RunClock(bench.run_time, bench.wait_s)
        yield Simulation(pointed, scale, devices, positions, bench, clock)
    finally:
        bench.stop()


def tables_estimate(cfg: InstrumentConfig, plan: Plan, sched: Schedule) -> TablesEstimate:
    """The multiple-scattering table planes a scan of `sched` on the config's emulated bench
    would walk before its first move (those the cache does not hold), and the time that takes
    on this machine now (sim.bench.tables.estimate)."""
    return tables.estimate(_bench(cfg, plan), _positions(sched.readings, cfg.axes))


def beam_over_range(cfg: InstrumentConfig, plan: Plan, sched: Schedule) -> float | None:
    """The fixed range (W) the schedule's beam readings are taken on if the emulated bench's
    beam, at the start, reaches its full scale (each reading over range: flagged saturated,
    normalising nothing), else None."""
    beam = sched.readings[(sched.readings["kind"] == "beam")
                          & (sched.readings["range_w"] != AUTO_RANGE)]
    if len(beam) == 0:
        return None
    power = _bench(cfg, plan).power_w(_positions(beam[:1], cfg.axes)[0])
    full_scale = float(beam["range_w"].min())
    return full_scale if power >= full_scale else None


def _bench(cfg: InstrumentConfig, plan: Plan) -> Bench:
    """The config's emulated bench with the plan's sample mounted; a ConfigError names a bad
    [sim] table."""
    try:
        return build_bench(cfg.sim, cfg.raw.get("optics"), plan.raw.get("sample"))
    except ValueError as exc:
        raise ConfigError(f"{cfg.path or 'config'}: {exc}") from None


def emulated_time_scale(cfg: InstrumentConfig) -> float:
    """The [sim] time_scale the emulated stages move at: virtual seconds per real second
    (inf: moves complete at once)."""
    try:
        return time_scale_of(cfg.sim)
    except ValueError as exc:
        raise ConfigError(f"{cfg.path or 'config'}: {exc}") from None


def with_time_scale(cfg: InstrumentConfig, value: float) -> InstrumentConfig:
    """A copy of the config whose [sim] time_scale is value (`--time-scale X`; inf = instant
    moves)."""
    if not value > 0:
        raise ConfigError(f"--time-scale must be > 0 (or inf), got {value!r}")
    scale = "inf" if math.isinf(value) else float(value)
    return parse_config({**cfg.raw, "sim": {**cfg.sim, "time_scale": scale}}, cfg.path)


def serve(cfg: InstrumentConfig, time_scale: float | None = None,
          bind: str = LOOPBACK) -> EmulatedBench:
    """Start every device of a config (for `gonio emulate`), at time_scale if given instead
    of the config's, Modbus TCP ones listening on `bind`; the caller stops the bench."""
    if time_scale is not None:
        cfg = with_time_scale(cfg, time_scale)
    return _start(cfg, list(cfg.devices), {}, bind=bind)
