"""Build an instrument (Axis, Detector and EnvironmentSensor drivers) from a validated config.

Each device opens through its kind (gonio.device_kinds); this module opens them, shares a
multi-axis controller among its axes, pushes the config's motion settings and travel limits
to every axis (`Axis.configure`), records what each device reports (its identity when
opened, what its line has seen when the run ends), and closes everything again.
"""

from __future__ import annotations

import contextlib
import math
import termios
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.base import Axis, Detector, DriverError, EnvironmentSensor, LineCounts
from gonio.config import InstrumentConfig
from gonio.device_kinds import DeviceConfig
from gonio.device_kinds.kind import AxisConfig
from gonio.errors import ConfigError
from gonio.events import Stopping

STOP_ATTEMPTS = 2


@dataclass
class Instrument:
    """Live drivers for a config: axes by role, the detector, the environment sensor (None:
the config has none), and how to close them.

    time_scale: virtual seconds per real second of the devices (1 on a real bench; the
    emulators' scale under --sim), so that settle and dwell waits shrink with it.
    devices: per device name, its protocol, endpoint (and Modbus unit) and the identity it
    reported when opened.
    """

    config: InstrumentConfig
    axes: dict[str, Axis]
    detector: Detector
    closers: list[Callable[[], None]] = field(default_factory=list)
    time_scale: float = 1.0
    devices: dict[str, dict[str, Any]] = field(default_factory=dict)
    environment: EnvironmentSensor | None = None

    def stop_all(self) -> dict[str, str]:
        """Ask every axis to stop, each whatever the others did, twice if the first answer is
        lost (a stop is safe to repeat; a fault or a transaction a signal cut short can eat
        its confirmation); returns {role: error} for those that could not be told (a lost
        device: its port gone, no reply)."""
        failed = {}
        for role, axis in self.axes.items():
            for attempt in range(STOP_ATTEMPTS):
                try:
                    axis.stop()
                    break
                except (DriverError, OSError, termios.error) as exc:
                    if attempt + 1 == STOP_ATTEMPTS:
                        failed[role] = str(exc) or type(exc).__name__
        return failed

    def line_counts(self) -> dict[str, dict[str, int]]:
        """Per device whose driver counts them (drivers.base.LineCounts), what its line has
        seen since it was opened: resyncs, unsolicited lines set aside."""
        drivers = drivers_by_device(self.config, self.axes, self.detector, self.environment)
        return {name: driver.line_counts() for name, driver in drivers.items()
                if isinstance(driver, LineCounts)}

    def record_lines(self, event: object) -> None:
        """A subscriber to the engine's events: the session's record gets `lines` (what
        line_counts says) as the run ends."""
        if isinstance(event, Stopping):
            event.session.update(lines=self.line_counts())

    def close(self) -> None:
        """Close every device connection (errors while closing are ignored)."""
        close_all(self.closers)

    def __enter__(self) -> Instrument:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def close_all(closers: list[Callable[[], None]]) -> None:
    """Call every close kept, last opened first, whatever each raises; empty the list."""
    for close in reversed(closers):
        with contextlib.suppress(Exception):
            close()
    closers.clear()


def drivers_by_device(cfg: InstrumentConfig, axes: dict[str, Axis], detector: Detector,
                      environment: EnvironmentSensor | None = None
                      ) -> dict[str, Axis | Detector | EnvironmentSensor]:
    """One driver per device name (an axis of a multi-axis controller speaks for it)."""
    drivers: dict[str, Axis | Detector | EnvironmentSensor] = {
        cfg.axes[role].device: axis for role, axis in axes.items()}
    drivers[cfg.detector.device] = detector
    if environment is not None and cfg.environment is not None:
        drivers[cfg.environment] = environment
    return drivers


def open_device(dev: DeviceConfig, closers: list[Callable[[], None]]) -> Any:
    """The device opened through its kind (one ConfigError if it cannot be reached), its
    close kept for the end."""
    try:
        opened = dev.kind.open(dev)
    except DriverError:
        raise
    except (OSError, ValueError) as exc:
        raise ConfigError(f"devices.{dev.name}: cannot open {dev.protocol} at "
                          f"{dev.endpoint}: {exc}") from None
    closers.append(opened.close)
    return opened


def axis_of(dev: DeviceConfig, ax: AxisConfig, opened: Any) -> Axis:
    """The Axis driver of a role on its opened device: a multi-axis controller's axis (named
    `device.role`), or the device itself."""
    return opened.axis(ax.axis, f"{dev.name}.{ax.role}") if dev.kind.multi_axis else opened


def _stage(dev: DeviceConfig, ax: AxisConfig, controllers: dict[str, Any],
           closers: list[Callable[[], None]]) -> Axis:
    """An Axis driver for a role, with the config's speed, acceleration and limits set; the
    axes of a multi-axis controller share its one connection."""
    if dev.kind.multi_axis:
        if dev.name not in controllers:
            controllers[dev.name] = open_device(dev, closers)
        axis = axis_of(dev, ax, controllers[dev.name])
    else:
        axis = axis_of(dev, ax, open_device(dev, closers))
    axis.configure(ax.speed_deg_s, ax.accel_deg_s2, ax.limits_deg)
    return axis


def build_instrument(cfg: InstrumentConfig, time_scale: float = 1.0) -> Instrument:
    """Open every device of the config and return the instrument (close it when done)."""
    if not time_scale > 0:
        raise ValueError(f"time_scale must be > 0 (or inf), got {time_scale!r}")
    closers: list[Callable[[], None]] = []
    controllers: dict[str, Any] = {}
    try:
        axes = {role: _stage(cfg.devices[ax.device], ax, controllers, closers)
                for role, ax in cfg.axes.items()}
        detector = open_device(cfg.devices[cfg.detector.device], closers)
        environment = (None if cfg.environment is None
                       else open_device(cfg.devices[cfg.environment], closers))
        drivers = drivers_by_device(cfg, axes, detector, environment)  # an ESP's axes alike
        devices = {name: _record(cfg.devices[name], drivers[name])
                   for name in cfg.devices if name in drivers}
    except BaseException:
        close_all(closers)
        raise
    return Instrument(cfg, axes, detector, closers, time_scale=float(time_scale),
                      devices=devices, environment=environment)


def _record(dev: DeviceConfig, driver: Axis | Detector | EnvironmentSensor) -> dict[str, Any]:
    """What a run records of a device: protocol, endpoint, the settings its kind records (a
    Modbus transport and unit), and the identity the driver reports; a device that reports
    none, or fails to, is noted, never fatal."""
    record: dict[str, Any] = {"protocol": dev.protocol, "endpoint": dev.endpoint,
                              **dev.recorded}
    try:
        record["identity"] = driver.identity()
    except DriverError as exc:
        record["identity"] = {}
        record["identity_note"] = f"identity not read: {exc}"
    else:
        if not record["identity"]:
            record["identity_note"] = "the device reported no identity"
    return record


def real_seconds(instrument: Instrument, seconds: float) -> float:
    """Real seconds a device-time wait lasts on this instrument (0 when time is instant)."""
    return 0.0 if math.isinf(instrument.time_scale) else seconds / instrument.time_scale
