"""The scan engine: for each scheduled reading move the axes together, wait, settle, read, record.

Failures: a device that reports an error (DeviceError) is not retried; a timeout, garbled reply
or lost connection is retried (the whole point: absolute moves and reads are safe to repeat)
up to `retries` times, after which the run stops cleanly with the reason recorded. An invalid
reading (the detector has none: InvalidReading) is retried the same way and, if every try
gives one, recorded with power NaN and the flag "invalid", and the run goes on. Ctrl-C once
pauses at the next point (resume or abort at the prompt; end of input aborts); a second Ctrl-C
aborts at once; SIGTERM and SIGHUP abort at once (reason: the signal's name). However a run
ends short of completion (abort, signal, failure, an exception, a full disk), every axis that
can be reached is told to stop, those that cannot are recorded, and meta.json gets the status
and reason where the disk allows it; while that happens further signals are ignored. A plan's
prompted signature pass (`[signature] pass = "prompted"`) waits for the operator to remove the
sample before its first reading (in every session that reaches it: a resume inside the pass
asks again).
"""

from __future__ import annotations

import math
import signal
import sys
import termios
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import DeviceError, DriverError, InvalidReading, Reading
from gonio.errors import Terminated
from gonio.geometry import sample_angles
from gonio.instrument import Instrument, real_seconds
from gonio.plan import (
    AUTO_RANGE,
    MOTION_ROLES,
    Plan,
    describe_range,
    profile_seconds,
    sweeps_source,
)
from gonio.progress import Progress
from gonio.reading_flags import INVALID, RETRIED
from gonio.store import RunWriter, StoreError

# Failures worth retrying: driver timeouts/garbles and lost connections (pyserial lets
# termios.error, which is no OSError, through when a pty or USB port goes away).
TRANSIENT = (DriverError, OSError, termios.error)
WAIT_FACTOR = 2.0  # motion timeout = WAIT_FACTOR x profile time + WAIT_MARGIN_S
WAIT_MARGIN_S = 5.0
RETRY_PAUSE_S = 0.05


class StopRun(Exception):
    """The run cannot go on; the message is the reason recorded in meta.json."""


class PositionMismatch(DriverError):
    """An axis reports a position other than the target it was sent to (twice running)."""


class Aborted(Exception):
    """The user aborted the run."""


TERMINATING = (signal.SIGTERM, signal.SIGHUP)
HANDLED = (signal.SIGINT, *TERMINATING)


@dataclass
class Outcome:
    """How a run (session) ended."""

    status: str  # completed | aborted | failed
    reason: str
    done: int  # readings stored in total
    signum: int | None = None  # the signal that ended it (SIGTERM, SIGHUP)


def ask_resume() -> bool:
    """Default pause prompt (on stderr, answer on stdin): True to resume, False to abort.
    End of input counts as abort."""
    while True:
        sys.stderr.write("paused: [r]esume or [a]bort? ")
        sys.stderr.flush()
        line = sys.stdin.readline()
        if not line:
            return False
        answer = line.strip().lower()
        if answer in ("r", "resume", ""):
            return True
        if answer in ("a", "abort"):
            return False


def ask_continue(message: str) -> bool:
    """Default operator prompt (on stderr, answer on stdin): True to continue, False to abort.
    End of input counts as abort."""
    while True:
        sys.stderr.write(f"{message}: [c]ontinue or [a]bort? ")
        sys.stderr.flush()
        line = sys.stdin.readline()
        if not line:
            return False
        answer = line.strip().lower()
        if answer in ("c", "continue", ""):
            return True
        if answer in ("a", "abort"):
            return False


def _notify(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class PauseControl:
    """Signal handling for a run: the first SIGINT asks for a pause at the next point, the
    second aborts (KeyboardInterrupt); SIGTERM and SIGHUP raise Terminated. Entered more than
    once (the runner before it makes the run directory, the engine), the outermost counts."""

    def __init__(self, prompt: Callable[[], bool] = ask_resume,
                 notify: Callable[[str], Any] = _notify,
                 confirm: Callable[[str], bool] = ask_continue):
        self.prompt, self.notify, self.confirm = prompt, notify, confirm
        self.pause_requested = False
        self._previous: dict[int, Any] = {}
        self._depth = 0

    def _on_sigint(self, signum: int, frame: Any) -> None:
        self.pause_requested = True
        self.notify("pausing after this point (Ctrl-C again to abort)")
        signal.signal(signal.SIGINT, self._on_second_sigint)

    def _on_second_sigint(self, signum: int, frame: Any) -> None:
        self.hold()
        raise KeyboardInterrupt

    def _on_terminate(self, signum: int, frame: Any) -> None:
        self.hold()
        raise Terminated(signum)

    def hold(self) -> None:
        """Ignore these signals from now on (until the outermost exit): the run is ending, and
        stopping the axes and recording why must not be interrupted."""
        if self._previous:
            for sig in HANDLED:
                signal.signal(sig, signal.SIG_IGN)

    def __enter__(self) -> PauseControl:
        self._depth += 1
        if self._depth == 1 and threading.current_thread() is threading.main_thread():
            self.pause_requested = False
            self._previous = {sig: signal.getsignal(sig) or signal.SIG_DFL for sig in HANDLED}
            for sig in HANDLED:  # one ignored on entry (nohup, a background job) stays so
                if self._previous[sig] is not signal.SIG_IGN:
                    signal.signal(sig, self._on_sigint if sig == signal.SIGINT
                                  else self._on_terminate)
        return self

    def __exit__(self, *exc: object) -> None:
        self._depth -= 1
        if self._depth == 0:
            for sig, previous in self._previous.items():
                signal.signal(sig, previous)
            self._previous = {}

    def checkpoint(self, on_pause: Callable[[str], None]) -> None:
        """Between points: if a pause was asked for, prompt; raise Aborted to abort."""
        if not self.pause_requested:
            return
        on_pause("paused")
        try:
            resume = self.prompt()
        except (KeyboardInterrupt, EOFError):
            resume = False
        if not resume:
            raise Aborted("aborted by the user")
        self.pause_requested = False
        if self._previous.get(signal.SIGINT, signal.SIG_IGN) is not signal.SIG_IGN:
            signal.signal(signal.SIGINT, self._on_sigint)
        on_pause("running")

    def operator_step(self, message: str, on_pause: Callable[..., None]) -> None:
        """Wait for the operator to do what `message` asks by hand; raise Aborted to abort."""
        on_pause("paused", message)
        try:
            go_on = self.confirm(message)
        except (KeyboardInterrupt, EOFError):
            go_on = False
        if not go_on:
            raise Aborted(f"aborted by the user at: {message}")
        on_pause("running")


class Engine:
    """Runs the remaining readings of a schedule on an instrument into a run writer."""

    def __init__(self, instrument: Instrument, plan: Plan, schedule: np.ndarray,
                 writer: RunWriter, *, retries: int = 2, progress: Progress | None = None,
                 control: PauseControl | None = None, t0_epoch: float | None = None,
                 session_info: Callable[[], dict[str, Any]] | None = None,
                 session: dict[str, Any] | None = None):
        self.inst, self.plan, self.schedule, self.writer = instrument, plan, schedule, writer
        self.retries = retries
        self.progress = progress
        self.control = control or PauseControl()
        self.t0 = t0_epoch if t0_epoch is not None else time.time()
        self.session_info = session_info
        self.session = session  # what RunWriter.start_session records; None: started already
        self._doing = "starting"
        self._commanded: dict[str, float | None] = {role: None for role in instrument.axes}
        self._reported: dict[str, float] = {role: 0.0 for role in MOTION_ROLES}
        cfg = instrument.config
        self._settle = {role: cfg.axes[role].settle_s for role in instrument.axes}
        self._range: float | None = None  # the detector range last set (schedule's range_w)

    # -- one reading ------------------------------------------------------------
    def _wait_timeout(self, role: str, target: float) -> float:
        ax = self.inst.config.axes[role]
        profile = float(profile_seconds(target - self._reported[role], ax.speed_deg_s,
                                        ax.accel_deg_s2))
        return WAIT_FACTOR * real_seconds(self.inst, profile) + WAIT_MARGIN_S

    def _move(self, row: np.void) -> list[str]:
        """Start every axis that must move, then wait for each; returns the roles moved."""
        targets = {role: float(row[f"{role}_deg"]) for role in self.inst.axes}
        moved = [r for r, t in targets.items() if self._commanded[r] != t]
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
        self.inst.last_positions.update(self._reported)
        return moved

    def _arrived(self, role: str, position: float, target: float) -> float:
        """The reported position, read again if it is off target (a garbled reply can be a
        plausible number); PositionMismatch if the second reading is off too."""
        tol = self.inst.config.axes[role].tolerance_deg
        if abs(position - target) <= tol:
            return position
        again = self.inst.axes[role].position()
        if abs(again - target) <= tol:
            return again
        raise PositionMismatch(f"{role} axis at {again:.6g} deg, not at its target "
                               f"{target:.6g} deg (tolerance {tol:g})")

    def _use_range(self, range_w: float) -> None:
        """Set the detector's range (AUTO_RANGE: autorange) unless it is set already."""
        if range_w == self._range:
            return
        det = self.inst.config.detector
        self._doing = f"setting the detector ({self.inst.detector.name}) range"
        self._range = None  # unknown until the device confirms
        self.inst.detector.configure(det.wavelength_nm, self.plan.averaging or det.averaging,
                                     None if range_w == AUTO_RANGE else range_w)
        self._range = range_w

    def _measure(self, row: np.void, flags: list[str]) -> dict[str, Any]:
        self._use_range(float(row["range_w"]))
        moved = self._move(row)
        pause = real_seconds(self.inst, max((self._settle[r] for r in moved), default=0.0)
                             + self.plan.dwell_s)
        if pause > 0:  # instant time: no sleep(0), which only yields the core away
            time.sleep(pause)
        self._doing = f"reading the detector ({self.inst.detector.name})"
        return self._record(row, self.inst.detector.read(), flags)

    def _record(self, row: np.void, reading: Reading, flags: list[str]) -> dict[str, Any]:
        """The stored line of a reading taken at the axes' reported positions."""
        pos = self._reported
        ang = sample_angles(pos["sample"], pos["arm"], pos["elevation"], pos["azimuth"])
        return {
            "index": int(row["index"]), "kind": str(row["kind"]), "side": str(row["side"]),
            "repeat": int(row["repeat"]), "point": int(row["point"]),
            **{f"{r}_deg": pos[r] for r in MOTION_ROLES},
            "theta_i_deg": float(ang.theta_i_deg), "phi_i_deg": float(ang.phi_i_deg),
            "theta_o_deg": float(ang.theta_o_deg), "phi_o_deg": float(ang.phi_o_deg),
            "plan_theta_i_deg": float(row["theta_i_deg"]),
            "plan_theta_o_deg": float(row["theta_o_deg"]),
            "plan_phi_o_deg": float(row["phi_o_deg"]),
            "power_w": float(reading.power_w), "range_w": float(reading.range_w),
            "saturated": bool(reading.saturated), "t_s": time.time() - self.t0,
            "flags": ",".join(flags),
        }

    def _with_retries(self, row: np.void) -> dict[str, Any]:
        where = f"reading {int(row['index'])} ({row['kind']})"
        flags: list[str] = []
        for attempt in range(self.retries + 1):
            try:
                return self._measure(row, flags)
            except DeviceError as exc:
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

    # -- the run ----------------------------------------------------------------
    def _check_ranges(self) -> None:
        """Before any motion: the detector accepts every range the remaining readings use (each
        set once; a PM100 refuses a range its sensor lacks, a Modbus amplifier one above its
        largest), so a bad plan range stops the run with one clear error."""
        remaining = self.schedule["range_w"][self.writer.todo(len(self.schedule))]
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
        cfg = self.inst.config
        try:
            self._check_ranges()
            for role, ax in cfg.axes.items():
                if ax.home:
                    self.inst.axes[role].home()
                    self.inst.axes[role].wait(WAIT_FACTOR * real_seconds(self.inst, 600.0)
                                              + WAIT_MARGIN_S)
                self._reported[role] = self.inst.axes[role].position()
        except TRANSIENT as exc:
            raise StopRun(f"preparing the instrument: {exc}") from exc

    def run(self) -> Outcome:
        """Start the session (if given one), measure every reading not yet stored; always
        stops the axes and leaves meta.json with the outcome where the disk allows it."""
        status, reason, signum = "completed", "", None
        with self.control:
            try:
                if self.session is not None:
                    self.writer.start_session(**self.session)
                self._prepare()
                rest = self.schedule[self.writer.todo(len(self.schedule))]
                prompt_at = self._operator_prompt_index(rest)
                for row in rest:
                    self.control.checkpoint(self._paused)
                    if int(row["index"]) == prompt_at:
                        self.control.operator_step(self._signature_message(rest), self._paused)
                    record = self._with_retries(row)
                    self.writer.append(record)
                    if self.progress:
                        self.progress.update(record)
                self.writer.wait_stored()  # the last fsync: a disk error fails here, not in _finish
            except (StopRun, StoreError) as exc:
                status, reason = "failed", str(exc)
            except Terminated as exc:
                status, reason, signum = "aborted", str(exc), exc.signum
            except (Aborted, KeyboardInterrupt) as exc:
                status, reason = "aborted", str(exc) or "aborted by the user (Ctrl-C)"
            except BaseException as exc:
                self.control.hold()
                self._finish("failed", f"internal error: {type(exc).__name__}: {exc}")
                raise
            self.control.hold()
            reason = self._finish(status, reason)
        return Outcome(status, reason, self.writer.stored, signum)
    def _operator_prompt_index(self, rest: np.ndarray) -> int:
        """Index of the first of the remaining readings `rest` in a prompted signature pass
        (-1: none)."""
        sig = self.plan.signature
        if sig is None or sig.mode != "prompted":
            return -1
        first = np.flatnonzero(rest["kind"] == "signature")
        return int(rest["index"][first[0]]) if len(first) else -1

    def _signature_message(self, rest: np.ndarray) -> str:
        """The operator prompt before a prompted signature pass among the readings `rest`."""
        n = int((rest["kind"] == "signature").sum())
        return (f"signature pass: remove the sample (nothing but the bench in the beam) for the "
                f"next {n} readings")

    def _paused(self, status: str, reason: str = "paused by the user") -> None:
        self.writer.set_status(status, reason if status == "paused" else "")

    def _finish(self, status: str, reason: str) -> str:
        """Stop every axis unless completed, record the outcome; returns the reason as
        recorded (with the axes that could not be stopped, or why it could not be recorded)."""
        if status != "completed":
            unstopped = self.inst.stop_all()
            if unstopped:
                self.writer.meta["unstopped"] = unstopped
                reason += "; could not stop: " + "; ".join(f"{role}: {why}"
                                                           for role, why in unstopped.items())
        if self.progress:
            self.progress.close()
        if self.session_info and self.writer.meta["sessions"]:
            self.writer.meta["sessions"][-1].update(self.session_info())
        try:
            self.writer.set_status(status, reason)
        except StoreError as exc:
            reason += f" (not recorded in meta.json: {exc})"
        return reason
