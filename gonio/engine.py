"""The scan engine: for each scheduled reading move the axes together, wait, settle, read, and
publish what happened (gonio.events); the run store, progress, the live view and the emulators
subscribe, and the engine knows none of them.

The engine runs the compiled, index-addressed schedule (what makes resume after a kill exact).
Of a schedule row it reads the index, the stage targets (`<role>_deg`) and the detector range
(`range_w`); every other field is a tag it copies into the stored line unread (a tag the
measurement also writes, such as theta_i_deg, is stored as plan_<name>). With an environment
sensor in the config, each reading's line also carries the room read right after the detector
(gonio.room_sensor: temperature_c, humidity_rel and their u).

Failures: a device that reports an error (DeviceError) is not retried; a timeout, garbled reply
or lost connection is retried (absolute moves and reads are safe to repeat) up to `retries`
times, after which the run stops cleanly with the reason recorded. An invalid reading
(InvalidReading) is retried the same way and, if every try gives one, recorded with power NaN
and the flag "invalid", and the run goes on until more readings are invalid than the plan's
`max_invalid_share` allows, or ends without one valid reading (gonio.invalid_readings):
then it fails, naming the detector. A reading's t_s and the waits (settling, dwell, a
suspension's recheck and timeout) are on the run's clock (gonio.run_clock: the wall clock, or
an all-emulated bench's virtual one). Pause, resume and abort come from the terminal and
the control channel (gonio.run_control); suspenders (gonio.suspenders) hold the run while a
condition lasts and measure the interrupted point again. However a run ends short of
completion (abort, signal, failure, an exception, a full disk), every axis that can be reached
is told to stop, those that cannot are recorded, and the Stopped event carries the status and
reason; while that happens further signals are ignored. Operator prompts (a prompted
signature pass) wait before the readings whose indices `prompts` names.
"""

from __future__ import annotations

import math
import termios
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import DeviceError, DriverError, Interlock, Interlocked, InvalidReading, Reading
from gonio.errors import Terminated
from gonio.events import (
    EventBus,
    Moved,
    Paused,
    ReadingDiscarded,
    ReadingStored,
    Resumed,
    RunStarted,
    State,
    Stopped,
    Stopping,
    Suspended,
    Suspension,
)
from gonio.geometry import sample_angles
from gonio.instrument import Instrument, real_seconds
from gonio.invalid_readings import InvalidReadings
from gonio.plan import (
    AUTO_RANGE,
    MOTION_ROLES,
    Plan,
    describe_range,
    profile_seconds,
    sweeps_source,
)
from gonio.reading_flags import INVALID, RETRIED
from gonio.room_sensor import ROOM_FIELDS, room_readout
from gonio.row_step import RowStep, arrival, row_step
from gonio.run_clock import RunClock, wall_clock
from gonio.run_control import Aborted, PauseControl
from gonio.store import StoreError
from gonio.suspenders import Watch

# Failures worth retrying: driver timeouts/garbles and lost connections (pyserial lets
# termios.error, which is no OSError, through when a pty or USB port goes away).
TRANSIENT = (DriverError, OSError, termios.error)
WAIT_FACTOR = 2.0  # motion timeout = WAIT_FACTOR x profile time + WAIT_MARGIN_S
WAIT_MARGIN_S = 5.0
HOME_S = 600.0  # device seconds a homing move may take
RETRY_PAUSE_S = 0.05
MEASURED = ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg", "power_w", "saturated",
            "t_s", "flags", *ROOM_FIELDS)  # what a stored line says of the measurement itself


def motion_timeout_s(instrument: Instrument, role: str, distance_deg: float) -> float:
    """How long a move of distance_deg on the role's axis may take, real seconds: WAIT_FACTOR
    times its velocity profile on the instrument's clock, plus WAIT_MARGIN_S."""
    ax = instrument.config.axes[role]
    profile = float(profile_seconds(distance_deg, ax.speed_deg_s, ax.accel_deg_s2))
    return WAIT_FACTOR * real_seconds(instrument, profile) + WAIT_MARGIN_S


def home_axes(instrument: Instrument) -> None:
    """Home the axes whose config asks for it, one after another, each allowed HOME_S of
    device time."""
    for role, ax in instrument.config.axes.items():
        if ax.home:
            instrument.axes[role].home()
            instrument.axes[role].wait(WAIT_FACTOR * real_seconds(instrument, HOME_S)
                                       + WAIT_MARGIN_S)


def configure_detector(instrument: Instrument, plan: Plan, range_w: float | None) -> None:
    """Set the detector's correction wavelength ([detector] / [optics]), the samples it
    averages (the plan's, else the config's) and its range (None: autorange)."""
    det = instrument.config.detector
    instrument.detector.configure(det.wavelength_nm, plan.averaging or det.averaging, range_w)


class StopRun(Exception):
    """The run cannot go on; the message is the reason recorded in meta.json. `resumable`:
    whether `gonio scan --resume` can finish the run once the cause is fixed (not when the
    readings already stored are what stopped it)."""

    def __init__(self, reason: str, resumable: bool = True):
        super().__init__(reason)
        self.resumable = resumable


@dataclass
class Outcome:
    """How a run (session) ended."""

    status: str  # completed | aborted | failed
    reason: str
    done: int  # readings stored in total
    signum: int | None = None  # the signal that ended it (SIGTERM, SIGHUP)
    resumable: bool = True  # whether `gonio scan --resume` can finish it (StopRun.resumable)
    unrecorded: str = ""  # why meta.json could not record this ending ("": it did)


def _plain(value: Any) -> Any:
    """A schedule field's value as JSON takes it: a numpy scalar's Python value; an object
    field (text) as it is."""
    return value.item() if isinstance(value, np.generic) else value


def schedule_tags(readings: np.ndarray) -> list[tuple[str, str]]:
    """(schedule field, stored field) of every tag of a schedule: the fields the engine does
    not interpret, stored under their own name, or plan_<name> where the measurement writes
    that name."""
    interpreted = {"index", "range_w", *(f"{role}_deg" for role in MOTION_ROLES)}
    return [(name, f"plan_{name}" if name in MEASURED else name)
            for name in readings.dtype.names if name not in interpreted]


class Engine:
    """Runs the readings `todo` (indices into the schedule `readings`) on an instrument and
    publishes what happens on `bus`; `session` is what the RunStarted event carries for the
    session record, `prompts` the operator prompts by reading index, `watch` the suspenders
    (None: none), `invalid` the count of invalid readings (with those stored before this
    session; gonio.invalid_readings), `clock` the run's clock (None: the wall clock since
    t0_epoch)."""

    def __init__(self, instrument: Instrument, plan: Plan, readings: np.ndarray,
                 todo: list[int], bus: EventBus, *, stored: int = 0, retries: int = 2,
                 control: PauseControl | None = None, t0_epoch: float | None = None,
                 session: dict[str, Any] | None = None, prompts: dict[int, str] | None = None,
                 watch: Watch | None = None, invalid: InvalidReadings | None = None,
                 clock: RunClock | None = None):
        self.inst, self.plan, self.readings, self.todo = instrument, plan, readings, todo
        self.bus, self.stored, self.retries = bus, stored, retries
        self.control = control or PauseControl()
        self.clock = clock or wall_clock(time.time() if t0_epoch is None else t0_epoch,
                                         instrument.time_scale)
        self.session = session or {}
        self.prompts = prompts or {}
        self.watch = watch
        self.invalid = invalid or InvalidReadings(instrument.detector.name, len(readings),
                                                  plan.max_invalid_share)
        self._tags = schedule_tags(readings)
        self._doing = "starting"
        self._sent: Stopping | None = None  # the last Stopping published
        self._commanded: dict[str, float | None] = {role: None for role in instrument.axes}
        self._reported: dict[str, float] = {role: 0.0 for role in MOTION_ROLES}
        self._range: float | None = None  # the detector range last set (schedule's range_w)
        self._room = room_readout(instrument.environment, instrument.config.raw,
                                  instrument.config.environment)

    # -- one reading ------------------------------------------------------------
    def _wait_timeout(self, role: str, target: float) -> float:
        return motion_timeout_s(self.inst, role, target - self._reported[role])

    def _move(self, row: np.void, step: RowStep) -> None:
        """Start every axis the step moves, then wait for each and check its arrival."""
        targets, moved = step.targets, step.moved
        if "arm" in moved and sweeps_source(self._reported["arm"], targets["arm"]):
            raise StopRun(f"reading {int(row['index'])}: the arm would sweep through the source "
                          f"({self._reported['arm']:g} -> {targets['arm']:g} deg); not moved")
        for role in moved:
            self._commanded[role] = None  # unknown until the move is confirmed done
            self._doing = f"moving the {role} axis ({self.inst.axes[role].name})"
            self.inst.axes[role].move_to(targets[role])
        for role in moved:
            axis, target = self.inst.axes[role], targets[role]
            self._doing = f"waiting for the {role} axis ({axis.name})"
            self._reported[role] = self._arrived(role, axis.wait(self._wait_timeout(role, target)),
                                                 target)
            self._commanded[role] = target
        self.bus.publish(Moved(int(row["index"]), dict(self._reported)))

    def _arrived(self, role: str, position: float, target: float) -> float:
        """The reported position, once the arrival check (gonio.row_step) holds for it."""
        check = arrival(self.inst, role, target)
        return position if check.holds(position) else check.confirm(
            self.inst.axes[role].position())

    def _use_range(self, range_w: float) -> None:
        """Set the detector's range (AUTO_RANGE: autorange) unless it is set already."""
        if range_w == self._range:
            return
        self._doing = f"setting the detector ({self.inst.detector.name}) range"
        self._range = None  # unknown until the device confirms
        configure_detector(self.inst, self.plan, None if range_w == AUTO_RANGE else range_w)
        self._range = range_w

    def _measure(self, row: np.void, flags: list[str]) -> dict[str, Any]:
        step = row_step(self.inst, row, self._commanded, self.plan.dwell_s)
        self._use_range(step.range_w)
        self._move(row, step)
        pause_s = self.clock.device_wait_s(step.hold_s)
        if pause_s > 0:  # instant time: no sleep(0), which only yields the core away
            time.sleep(pause_s)
        self._doing = f"reading the detector ({self.inst.detector.name})"
        record = self._record(row, self.inst.detector.read(), flags)
        if self._room is not None:
            self._doing = f"reading the environment sensor ({self._room.sensor.name})"
            record.update(self._room.read())
        return record

    def _record(self, row: np.void, reading: Reading, flags: list[str]) -> dict[str, Any]:
        """The stored line of a reading taken at the axes' reported positions: the row's
        index and tags, the positions and the measurement."""
        pos = self._reported
        ang = sample_angles(pos["sample"], pos["arm"], pos["elevation"], pos["azimuth"])
        return {
            "index": int(row["index"]),
            **{stored: _plain(row[name]) for name, stored in self._tags},
            **{f"{r}_deg": pos[r] for r in MOTION_ROLES},
            "theta_i_deg": float(ang.theta_i_deg), "phi_i_deg": float(ang.phi_i_deg),
            "theta_o_deg": float(ang.theta_o_deg), "phi_o_deg": float(ang.phi_o_deg),
            "power_w": float(reading.power_w), "range_w": float(reading.range_w),
            "saturated": bool(reading.saturated), "t_s": self._now(),
            "flags": ",".join(flags),
        }

    def _now(self) -> float:
        """Seconds since the run's first start (the clock of t_s)."""
        return self.clock.now()

    def _with_retries(self, row: np.void) -> dict[str, Any]:
        where = f"reading {int(row['index'])} ({row['kind']})" if "kind" in row.dtype.names \
            else f"reading {int(row['index'])}"
        flags: list[str] = []
        for attempt in range(self.retries + 1):
            try:
                return self._measure(row, flags)
            except DeviceError as exc:
                if isinstance(exc, Interlocked) and self.watch and self.watch.spec.interlock:
                    raise
                raise StopRun(f"{where}: {self._doing}: {exc}") from exc
            except TRANSIENT as exc:
                last = exc
                if RETRIED not in flags:
                    flags.append(RETRIED)
                self._commanded = dict.fromkeys(self._commanded)
                if attempt < self.retries:
                    time.sleep(RETRY_PAUSE_S)
        if isinstance(last, InvalidReading):  # the axes arrived; the detector had no reading
            return self._record(row, Reading(math.nan, last.range_w), [*flags, INVALID])
        raise StopRun(f"{where}: {self._doing}: {last} (after {self.retries + 1} attempts)")

    # -- suspenders -------------------------------------------------------------
    def _attempt(self, row: np.void, interlocked: bool) -> tuple[str | None, dict | None]:
        """One try at a reading under the suspenders: (None, record) to store, or (why, None)
        while a suspender holds (the reading, if one was taken, discarded)."""
        if interlocked:
            held = self._interlock_held()
            if held:
                return held, None
        try:
            record = self._with_retries(row)
        except Interlocked as exc:
            self._commanded = dict.fromkeys(self._commanded)  # stopped wherever it was
            return f"interlock: {exc}", None
        why = self.watch.verdict(record)
        if why:
            self.bus.publish(ReadingDiscarded(row, why))
            return why, None
        return None, record

    def _interlock_held(self) -> str | None:
        """What still holds an interlock (each device that reports one asked to get ready)."""
        devices = {id(d): d for d in (*self.inst.axes.values(), self.inst.detector)}
        for device in devices.values():
            if isinstance(device, Interlock):
                try:
                    held = device.release_interlock()
                except TRANSIENT as exc:
                    held = f"{device.name}: {exc}"
                if held:
                    return f"interlock: {held}"
        return None

    def _reading(self, row: np.void) -> dict[str, Any]:
        """The reading of a row; with suspenders, held while one of them objects and measured
        again until none does (StopRun past the suspenders' timeout)."""
        if self.watch is None:
            return self._with_retries(row)
        index, suspension, deadline = int(row["index"]), None, 0.0
        while True:
            why, record = self._attempt(row, suspension is not None)
            if why is None:
                if suspension is not None:
                    suspension.resumed_t_s = self._now()
                    self.control.enter(State.RUNNING)
                    self.bus.publish(Resumed(index, suspension))
                return record
            if suspension is None:
                suspension = Suspension(why, index, self._now())
                deadline = suspension.t_s + self.watch.spec.timeout_s
                self.control.enter(State.SUSPENDED)
                self.bus.publish(Suspended(suspension))
            elif self._now() > deadline:
                raise StopRun(f"reading {index}: suspended ({suspension.reason}) and not "
                              f"cleared within {self.watch.spec.timeout_s:g} s: {why}")
            self.control.wait(self.clock.wait_s(self.watch.spec.recheck_s))

    # -- the run ----------------------------------------------------------------
    def _check_ranges(self) -> None:
        """Before any motion: the detector accepts every range the remaining readings use (each
        set once; a PM100 refuses a range its sensor lacks, a Modbus amplifier one above its
        largest), so a bad plan range stops the run with one clear error."""
        remaining = self.readings["range_w"][self.todo]
        for range_w in np.unique(remaining):
            try:
                self._use_range(float(range_w))
            except (DeviceError, ValueError) as exc:
                raise StopRun(f"the plan's detector range {describe_range(float(range_w))}: "
                              f"the detector refuses it ({exc})") from exc
        if len(remaining):
            self._use_range(float(remaining[0]))

    def _prepare(self) -> None:
        """Configure the detector on every range the plan uses (ending on the first reading's),
        home the axes that ask for it, learn where every axis is (the first move's timeout
        depends on it)."""
        try:
            self._check_ranges()
            home_axes(self.inst)
            for role, axis in self.inst.axes.items():
                self._reported[role] = axis.position()
        except TRANSIENT as exc:
            raise StopRun(f"preparing the instrument: {exc}") from exc

    def run(self) -> Outcome:
        """Start the session, measure every reading of `todo`; always stops the axes and ends
        with a Stopped event carrying the outcome."""
        status, reason, signum, resumable = "completed", "", None, True
        with self.control:
            try:
                self.bus.publish(RunStarted(len(self.readings), self.stored, tuple(self.todo),
                                            self.session))
                self._prepare()
                self.control.enter(State.RUNNING)
                for index in self.todo:
                    row = self.readings[index]
                    self.control.checkpoint(lambda i=index: self._paused(i),
                                            lambda i=index: self.bus.publish(Resumed(i)))
                    if index in self.prompts:
                        self.control.operator_step(
                            self.prompts[index], lambda why, i=index: self.bus.publish(
                                Paused(i, why)), lambda i=index: self.bus.publish(Resumed(i)))
                    record = self._reading(row)
                    self.bus.publish(ReadingStored(record, row))
                    self.stored += 1
                    if self.watch:
                        self.watch.accept(record)
                    self._count_invalid(record)
                if self.invalid.none_valid():
                    raise StopRun(self.invalid.none_valid(), resumable=False)
                self._stopping("completed", "")  # the last fsync: a refused one fails the run
            except (StopRun, StoreError) as exc:
                status, reason = "failed", str(exc)
                resumable = getattr(exc, "resumable", True)
            except Terminated as exc:
                status, reason, signum = "aborted", str(exc), exc.signum
            except (Aborted, KeyboardInterrupt) as exc:
                status = "aborted"
                reason = self.control.abort_reason or str(exc) or "aborted by the user (Ctrl-C)"
            except BaseException as exc:
                self.control.hold()
                self._finish("failed", f"internal error: {type(exc).__name__}: {exc}")
                raise
            self.control.hold()
            stopped = self._finish(status, reason)
        return Outcome(status, stopped.reason, self.stored, signum, resumable,
                       "; ".join(stopped.unrecorded))

    def _count_invalid(self, record: dict[str, Any]) -> None:
        """Count a stored reading; StopRun once the plan's share of invalid readings can no
        longer be met."""
        self.invalid.count(record)
        too_many = self.invalid.too_many()
        if too_many:
            raise StopRun(too_many, resumable=False)

    def _paused(self, index: int) -> None:
        self.bus.publish(Paused(index, self.control.pause_reason()))

    def _stopping(self, status: str, reason: str) -> None:
        """Publish that the run ends with `status` (once per status)."""
        self.control.enter(State.STOPPING)
        if self._sent is None or self._sent.status != status:
            self._sent = Stopping(status, reason)
            self.bus.publish(self._sent)

    def _finish(self, status: str, reason: str) -> Stopped:
        """Stop every axis unless completed, publish the end; returns it as published (its
        reason with the axes that could not be stopped, and whether the store recorded it)."""
        unstopped = self.inst.stop_all() if status != "completed" else {}
        if unstopped:
            reason += "; could not stop: " + "; ".join(f"{role}: {why}"
                                                       for role, why in unstopped.items())
        try:
            self._stopping(status, reason)
        except StoreError:
            pass  # the store notes at Stopped whether meta.json could record the end
        stopped = Stopped(status, reason, self.stored, unstopped,
                          self._sent.session if self._sent else {})
        self.bus.publish(stopped)
        self.control.enter(State(status))
        return stopped
