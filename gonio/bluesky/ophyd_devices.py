"""An instrument config's axes and detector as ophyd-async devices, for Bluesky's RunEngine.

Each axis is a movable, stoppable device with a readback that moves as gonio's engine moves
it (gonio's drivers, the same arrival timeout and tolerance, the arm never swept through the
source); the detector is triggerable and reads power, range and saturation. Driver calls are
blocking, so they run in worker threads; the drivers' transports serialise each exchange.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from bluesky.protocols import Location
from bluesky.run_engine import call_in_bluesky_event_loop, get_bluesky_event_loop
from ophyd_async.core import (
    AsyncStatus,
    Device,
    StandardReadable,
    soft_signal_r_and_setter,
    soft_signal_rw,
)
from ophyd_async.core import StandardReadableFormat as Format

from drivers.base import Axis, Detector
from gonio.config import InstrumentConfig, load_config
from gonio.engine import TRANSIENT, home_axes, motion_timeout_s
from gonio.instrument import Instrument, build_instrument
from gonio.plan import AUTO_RANGE, Plan, build_schedule, describe_range, load_plan, sweeps_source
from gonio.row_step import PositionMismatch, arrival
from gonio.run_clock import RunClock, wall_clock

if TYPE_CHECKING:
    from gonio.simulate import Simulation

T = TypeVar("T")
FAILURES = (*TRANSIENT, ValueError)  # a driver's ValueError: a value the device cannot take


class DeviceFailure(RuntimeError):
    """A gonio driver failed under Bluesky; `device` is the Bluesky device's name and the
    message also carries the driver's own (its config device and role)."""

    def __init__(self, device: str, action: str, exc: BaseException):
        self.device = device
        super().__init__(f"{device}: {action}: {exc}")


async def _call(device: str, action: str, fn: Callable[..., T], *args: Any) -> T:
    """A blocking driver call in a worker thread; its failures as a DeviceFailure."""
    try:
        return await asyncio.to_thread(fn, *args)
    except FAILURES as exc:
        raise DeviceFailure(device, action, exc) from exc


class GonioAxis(StandardReadable):
    """One axis of the config (its role is the device's name): `set` moves it and waits for
    the arrival, `stop` decelerates it, `read` reports where the device says it is now."""

    def __init__(self, role: str, driver: Axis, instrument: Instrument):
        self._role, self._driver, self._inst = role, driver, instrument
        self._config = instrument.config.axes[role]
        self._stopped: bool | None = None  # None: not stopped; else stop()'s success
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.readback, self._set_readback = soft_signal_r_and_setter(float, units="deg")
        self.setpoint, self._set_setpoint = soft_signal_r_and_setter(float, units="deg")
        super().__init__(name=role)

    def set_name(self, name: str, *, child_name_separator: str | None = None) -> None:
        """Name the device; its readback reads under the device's own name, as ophyd-async's
        motors do."""
        super().set_name(name, child_name_separator=child_name_separator)
        self.readback.set_name(name)

    async def position(self) -> float:
        """Ask the device where it is, and keep that as the readback."""
        where = await _call(self.name, "reading the position", self._driver.position)
        self._set_readback(where)
        return where

    def _refuse(self, start: float, target: float) -> None:
        lo, hi = self._config.limits_deg
        if not lo <= target <= hi:
            raise ValueError(f"{self.name}: {target:g} deg is outside its limits "
                             f"[{lo:g}, {hi:g}] deg; not moved")
        if self._role == "arm" and sweeps_source(start, target):
            raise ValueError(f"{self.name}: a move from {start:g} to {target:g} deg would sweep "
                             f"the arm through the source; not moved")

    async def check_value(self, value: float) -> None:
        """Bluesky's check before a move: within the limits, the arm clear of the source."""
        self._refuse(await self.position(), float(value))

    @AsyncStatus.wrap
    async def set(self, value: float) -> None:
        """Move to `value` deg and wait for the arrival (gonio's engine's timeout and arrival
        check, gonio.row_step); a stop ends it, as a failure unless stopped with success=True."""
        target = float(value)
        start = await self.position()
        self._refuse(start, target)
        self._stopped = None
        self._set_setpoint(target)
        await _call(self.name, f"moving to {target:g} deg", self._driver.move_to, target)
        timeout = motion_timeout_s(self._inst, self._role, target - start)
        arrived = await _call(self.name, f"waiting for the move to {target:g} deg",
                              self._driver.wait, timeout)
        self._set_readback(arrived)
        if self._stopped is not None:
            if self._stopped:
                return
            raise DeviceFailure(self.name, f"moving to {target:g} deg",
                                RuntimeError(f"stopped at {arrived:g} deg"))
        check = arrival(self._inst, self._role, target)
        if not check.holds(arrived):
            try:
                check.confirm(await self.position())
            except PositionMismatch as exc:
                raise DeviceFailure(self.name, f"moving to {target:g} deg", RuntimeError(
                    f"stopped at {exc.position_deg:.6g} deg, off target by more than "
                    f"{check.tolerance_deg:g} deg")) from exc

    async def stop(self, success: bool = True) -> None:
        """Decelerate to a stop (Bluesky's pause and abort call this)."""
        self._stopped = success
        await _call(self.name, "stopping", self._driver.stop)

    async def locate(self) -> Location[float]:
        """The last setpoint and where the device is now."""
        return Location(setpoint=await self.setpoint.get_value(),
                        readback=await self.position())

    async def read(self) -> dict[str, Any]:
        """The position the device reports now."""
        await self.position()
        return await super().read()


class RangeSetting(Device):
    """The detector's range as a movable: set a full scale in W, or gonio.plan.AUTO_RANGE (0)
    to autorange; the meter is configured with the config's wavelength and the detector's
    `averaging`."""

    def __init__(self, configure: Callable[[float], Any], name: str = ""):
        self._configure = configure
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def set(self, value: float) -> None:
        """Configure the meter on this range."""
        await self._configure(float(value))


class GonioDetector(StandardReadable):
    """The detector: `trigger` takes one (averaged) reading; `read` gives its power (W,
    hinted), the range it was read on (W) and whether it saturated. Its configuration is the
    correction wavelength and the averaging; `range_setting` sets the range."""

    def __init__(self, driver: Detector, instrument: Instrument, name: str = "detector"):
        self._driver = driver
        det = instrument.config.detector
        self._wavelength_nm = det.wavelength_nm
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.power_w, self._set_power = soft_signal_r_and_setter(float, units="W")
        with self.add_children_as_readables():
            self.range_w, self._set_range = soft_signal_r_and_setter(float, units="W")
            self.saturated, self._set_saturated = soft_signal_r_and_setter(bool)
        with self.add_children_as_readables(Format.CONFIG_SIGNAL):
            self.wavelength_nm = soft_signal_r_and_setter(float, det.wavelength_nm,
                                                          units="nm")[0]
            self.averaging = soft_signal_rw(int, det.averaging)
        self.range_setting = RangeSetting(self._configure)
        super().__init__(name=name)

    async def _configure(self, range_w: float) -> None:
        averaging = await self.averaging.get_value()
        await _call(self.name, f"setting the range to {describe_range(range_w)}",
                    self._driver.configure, self._wavelength_nm, averaging,
                    None if range_w == AUTO_RANGE else range_w)

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        """Take one reading."""
        reading = await _call(self.name, "reading", self._driver.read)
        self._set_power(float(reading.power_w))
        self._set_range(float(reading.range_w))
        self._set_saturated(bool(reading.saturated))


@dataclass
class GonioDevices:
    """The devices of one opened config: `axes` by role (also as attributes: `d.arm`), the
    `detector`, and the config and instrument they drive (under sim=True the config points at
    the emulators); `clock`, the run's clock a plan settles and dwells on (the emulated
    bench's virtual clock with every device emulated, else the wall clock); `emulation`, the
    running emulators under sim=True (gonio.simulate.Simulation), else None."""

    config: InstrumentConfig
    instrument: Instrument
    axes: dict[str, GonioAxis]
    detector: GonioDetector
    clock: RunClock
    emulation: Simulation | None = None

    def __getattr__(self, role: str) -> GonioAxis:
        axes = self.__dict__.get("axes", {})
        if role in axes:
            return axes[role]
        raise AttributeError(f"no {role!r} axis in this config (axes: {', '.join(axes)})")

    def all(self) -> list[Device]:
        """Every device, axes first."""
        return [*self.axes.values(), self.detector]


def _bluesky_loop_running() -> None:
    loop = get_bluesky_event_loop()
    if loop is None or not loop.is_running():
        raise RuntimeError("gonio.bluesky.devices: make the RunEngine first (its event loop "
                           "connects the devices)")


def _prepare(inst: Instrument) -> None:
    """Set the detector as the config has it and home the axes that ask for it, as gonio's
    engine does before a run."""
    det = inst.config.detector
    inst.detector.configure(det.wavelength_nm, det.averaging, det.range_w)
    home_axes(inst)


async def _connect(devs: GonioDevices) -> None:
    await asyncio.gather(*(d.connect() for d in devs.all()))
    await asyncio.gather(*(axis.position() for axis in devs.axes.values()))


@contextlib.contextmanager
def devices(config: str | Path | InstrumentConfig, sim: bool = False,
            sample: dict | None = None, plan: str | Path | Plan | None = None
            ) -> Iterator[GonioDevices]:
    """Open an instrument config's devices for Bluesky (make the RunEngine first); on leaving,
    every axis is told to stop and every connection closed. sim=True starts the emulators
    first, as `gonio scan --sim` does: `sample` is then a plan's [sample] table (the emulated
    sample's kind and index unless [sim] states them); `plan`, the gonio plan to be run, whose
    schedule's multiple-scattering tables are built before the first move (its [sample] is
    the sample unless `sample` is given)."""
    _bluesky_loop_running()
    cfg = config if isinstance(config, InstrumentConfig) else load_config(config)
    with contextlib.ExitStack() as stack:
        scale, emulation = 1.0, None
        if sim:
            from gonio.simulate import simulation

            upcoming = None
            if plan is not None:
                plan = plan if isinstance(plan, Plan) else load_plan(plan)
                upcoming = build_schedule(plan, cfg).readings
                sample = plan.raw.get("sample") if sample is None else sample
            emulation = stack.enter_context(simulation(cfg, sample=sample, upcoming=upcoming))
            cfg, scale = emulation.config, emulation.time_scale
        clock = emulation.clock if emulation is not None and emulation.clock is not None \
            else wall_clock(time.time(), scale)
        inst = stack.enter_context(build_instrument(cfg, scale))
        stack.callback(inst.stop_all)
        try:
            _prepare(inst)
        except FAILURES as exc:
            raise DeviceFailure(cfg.name, "preparing the instrument", exc) from exc
        devs = GonioDevices(cfg, inst, {role: GonioAxis(role, axis, inst)
                                        for role, axis in inst.axes.items()},
                            GonioDetector(inst.detector, inst), clock, emulation)
        call_in_bluesky_event_loop(_connect(devs))
        yield devs
