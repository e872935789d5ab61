"""Emulated Newport ESP300/ESP301 motion controller speaking its ASCII command set on a pty.

Written from the ESP301 user's manual (EDH0235En1030, section 3 "Remote mode" and the
command reference in section 3.7, error list in Appendix A): commands are
`[axis]XX[?][parameter]`, terminated by a carriage return; several commands on one line
are separated by ';'. Commands do not answer; queries answer with one line ended by CR LF
(several queries on one line: their answers joined by ',' on one line - our reading).
Errors are not answered either: they go into a 10-deep FIFO read with TE? (code) and TB?
("code, timestamp, MESSAGE", the timestamp in 400 us servo ticks since reset: ESP300
manual, TB command, p. 3-138); axis errors are numbered axis*100 + code.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import Counter, deque
from collections.abc import Mapping

from sim.devices.faults import FaultInjector, FaultSpec, InterlockInput
from sim.devices.motion import LimitError, MotionError, TrapezoidAxis, VirtualClock
from sim.devices.pty_server import PtyDevice, PtyServer

# General errors (ESP301 manual, Appendix A "Error messages"), the ones this emulator raises.
GENERAL_ERRORS = {
    0: "NO ERROR DETECTED",
    4: "EMERGENCY STOP ACTIVATED",
    6: "COMMAND DOES NOT EXIST",
    7: "PARAMETER OUT OF RANGE",
    9: "AXIS NUMBER OUT OF RANGE",
    37: "AXIS NUMBER MISSING",
    38: "COMMAND PARAMETER MISSING",
}
# Axis errors: reported as axis * 100 + code.
AXIS_ERRORS = {
    1: "PARAMETER OUT OF RANGE",
    6: "POSITIVE SOFTWARE LIMIT DETECTED",
    7: "NEGATIVE SOFTWARE LIMIT DETECTED",
    10: "MAXIMUM VELOCITY EXCEEDED",
    11: "MAXIMUM ACCELERATION EXCEEDED",
    13: "MOTOR NOT ENABLED",
    20: "HOMING ABORTED",
    26: "PARAMETER CHANGE NOT ALLOWED",
    30: "COMMAND NOT ALLOWED DURING HOMING",
}

# SN unit codes (ESP301 manual, SN command): only the angular ones make sense on a rotary
# stage; value in that unit per degree.
ANGULAR_UNITS = {7: 1.0, 8: 400.0 / 360.0, 9: math.pi / 180.0, 10: 1e3 * math.pi / 180.0,
                 11: 1e6 * math.pi / 180.0}
DEGREE = 7
SERVO_TICK_S = 400e-6  # TB? timestamps count servo interrupts (400 us by default)
# A wait or motion that would end later than this after power-up is a parameter out of range:
# TB?'s timestamp then stays an exact integer count of servo ticks (2**53, about 114000 years).
HORIZON_S = 2.0**53 * SERVO_TICK_S

AXIS_KEYS = {
    "limits_deg": (-170.0, 170.0),
    "speed_deg_s": 20.0,
    "accel_deg_s2": 80.0,
    "decel_deg_s2": None,  # None = accel_deg_s2
    "position_deg": 0.0,
    "max_speed_deg_s": 200.0,  # VU: VA above it is error x10
    "max_accel_deg_s2": 2000.0,  # AU: AC/AG above it is error x11
    "motor_on": False,  # the controller powers up with motors off (MO turns them on)
}

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_UNIT = re.compile(r"(\d*)([A-Z]{2})(\?)?(.*)")
QUERY_ONLY = {"TP", "MD", "TE", "TB", "VE"}
GLOBAL = {"TE", "TB", "VE", "AB"}  # no axis number
ALL_AXES_OPTIONAL = {"ST", "WS"}  # no axis number = every axis


class EspConfigError(ValueError):
    """An invalid axis table for the emulator (the message names the key)."""


class _Fail(Exception):
    """A command failed with an ESP error code (buffered, never answered)."""

    def __init__(self, code: int):
        self.code = code


class _EmulatedAxis:
    """One ESP axis: its trapezoidal motion plus the controller's per-axis settings."""

    def __init__(self, number: int, clock: VirtualClock, table: Mapping[str, object]):
        unknown = sorted(set(table) - set(AXIS_KEYS))
        if unknown:
            raise EspConfigError(
                f"esp axis {number}: unknown key {unknown[0]!r} (known: {', '.join(AXIS_KEYS)})"
            )
        cfg = {**AXIS_KEYS, **table}
        try:
            lo, hi = (float(v) for v in cfg["limits_deg"])  # type: ignore[union-attr]
            self.motion = TrapezoidAxis(
                clock, float(cfg["speed_deg_s"]), float(cfg["accel_deg_s2"]), (lo, hi),
                float(cfg["position_deg"]),
                None if cfg["decel_deg_s2"] is None else float(cfg["decel_deg_s2"]),
            )
        except (TypeError, ValueError) as exc:
            raise EspConfigError(f"esp axis {number}: {exc}") from None
        self.number = number
        self.max_speed = float(cfg["max_speed_deg_s"])
        self.max_accel = float(cfg["max_accel_deg_s2"])
        if self.motion.speed > self.max_speed or self.motion.accel > self.max_accel:
            raise EspConfigError(f"esp axis {number}: speed/accel above max_speed/max_accel")
        self.motor_on = bool(cfg["motor_on"])
        self.units = DEGREE
        self.homing = False

    def fail(self, code: int) -> _Fail:
        """This axis's error `code` as the controller numbers it (axis * 100 + code)."""
        return _Fail(self.number * 100 + code)

    @property
    def scale(self) -> float:
        """Value in the axis's display units per degree."""
        return ANGULAR_UNITS[self.units]

    def moving(self) -> bool:
        """True while in motion; a finished home search stops counting as homing."""
        moving = self.motion.is_moving()
        if not moving:
            self.homing = False
        return moving


class EspEmulator(PtyDevice):
    """An ESP300/ESP301 controller with rotary stages on a virtual clock, served on a pty.

    axes: {axis number: table} with keys of AXIS_KEYS (degrees); faults: injected on
    replies; seed: mixed into the fault RNG seed; estop: the emergency-stop input. When it
    opens the controller stops every axis at once, switches the motors off and logs error 4
    EMERGENCY STOP ACTIVATED; while it is open, MO is refused with that error.
    """

    protocol = "esp"

    def __init__(
        self,
        clock: VirtualClock | None = None,
        axes: Mapping[int, Mapping[str, object]] | None = None,
        faults: FaultSpec | None = None,
        seed: int = 0,
        model: str = "ESP301",
        estop: InterlockInput | None = None,
    ):
        self.clock = clock or VirtualClock(1.0)
        tables = axes if axes is not None else {1: {}, 2: {}}
        if not tables:
            raise EspConfigError("esp: at least one axis is needed")
        bad = [n for n in tables if not (isinstance(n, int) and 1 <= n <= 9)]
        if bad:
            raise EspConfigError(f"esp: axis numbers must be integers 1..9, got {bad[0]!r}")
        self.axes = {n: _EmulatedAxis(n, self.clock, t) for n, t in sorted(tables.items())}
        self.model = model
        self.version = f"{model} Version 3.0.2 (emulated)"
        self.errors: deque[tuple[int, int]] = deque(maxlen=10)
        self.received: Counter[str] = Counter()  # commands executed, by mnemonic
        self.estop, self._estop_open = estop, False
        self._lock = threading.RLock()
        self._stopping = threading.Event()
        self._server = PtyServer(
            self.handle_line, terminators=b"\r", ignore=b"\n", max_line=256,
            faults=FaultInjector(faults, seed=seed), reply_tail=2, name="esp",
        )

    # -- lifecycle --------------------------------------------------------------
    def stop(self) -> None:
        """Stop serving, end any wait for motion, and close the pty."""
        self._stopping.set()
        super().stop()

    def axis_position_deg(self, number: int) -> float:
        """Actual position of an axis now, degrees (for the optical bench)."""
        return self.axes[number].motion.position()

    # -- protocol ---------------------------------------------------------------
    def handle_line(self, line: bytes) -> bytes | None:
        """Execute one command line; returns the reply line (CR LF) or None."""
        text = line.decode("ascii", errors="replace")
        replies: list[str] = []
        with self._lock:
            self._watch_estop()
            for unit in text.split(";"):
                unit = unit.strip().replace(" ", "").replace("\t", "")
                if not unit:
                    continue
                try:
                    reply = self._execute(unit)
                except _Fail as fail:
                    self._log_error(fail.code)
                    continue
                if reply is not None:
                    replies.append(reply)
        return (",".join(replies) + "\r\n").encode("ascii") if replies else None

    def _watch_estop(self) -> None:
        """Act on the emergency-stop input: stop everything the moment it opens."""
        if self.estop is None:
            return
        tripped, self._estop_open = self.estop.poll()
        if tripped:
            for axis in self.axes.values():
                axis.motion.abort()
                axis.homing, axis.motor_on = False, False
            self._log_error(4)

    def _ticks(self) -> int:
        return int(self.clock.now() / SERVO_TICK_S)

    def _log_error(self, code: int) -> None:
        self.errors.append((code, self._ticks()))

    def _execute(self, unit: str) -> str | None:
        if unit.upper() == "*IDN?":
            return f"Newport Corporation,{self.model},0,3.0.2"
        match = _UNIT.fullmatch(unit.upper())
        if match is None:
            raise _Fail(6)
        digits, cmd, question, param = match.groups()
        handler = getattr(self, f"_cmd_{cmd.lower()}", None)
        if handler is None:
            raise _Fail(6)
        self.received[cmd + (question or "")] += 1
        query = question is not None or cmd in QUERY_ONLY
        if cmd in QUERY_ONLY and param:
            raise _Fail(7)
        if cmd in GLOBAL:
            return handler(None, query, param)
        if not digits:
            if cmd in ALL_AXES_OPTIONAL:
                return handler(None, query, param)
            raise _Fail(37)
        axis = self.axes.get(int(digits))
        if axis is None:
            raise _Fail(9)
        return handler(axis, query, param)

    @staticmethod
    def _number(param: str, required: bool = True) -> float | None:
        if not param:
            if required:
                raise _Fail(38)
            return None
        if _NUMBER.fullmatch(param) is None:
            raise _Fail(7)
        value = float(param)
        if not math.isfinite(value):
            raise _Fail(7)
        return value

    @staticmethod
    def _fmt(value: float) -> str:
        return f"{value:.5f}"

    # -- commands (each: axis or None, query flag, parameter text) ---------------
    def _move(self, axis: _EmulatedAxis, target_deg: float) -> None:
        if not axis.motor_on:
            raise axis.fail(13)
        if axis.homing and axis.moving():
            raise axis.fail(30)
        try:
            if not axis.motion.move_end(target_deg) <= HORIZON_S:
                raise axis.fail(1)
            axis.motion.move_to(target_deg)
        except LimitError as exc:
            raise axis.fail(6 if exc.side == "positive" else 7) from None
        except MotionError:
            raise axis.fail(1) from None

    def _cmd_pa(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """PA: move to absolute position; PA? the target (desired) position."""
        if query:
            return self._fmt(axis.motion.target() * axis.scale)
        self._move(axis, self._number(param) / axis.scale)
        return None

    def _cmd_pr(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """PR: move relative to the current target; PR? the target position."""
        if query:
            return self._fmt(axis.motion.target() * axis.scale)
        self._move(axis, axis.motion.target() + self._number(param) / axis.scale)
        return None

    def _cmd_tp(self, axis: _EmulatedAxis, query: bool, param: str) -> str:
        """TP / TP?: actual position."""
        return self._fmt(axis.motion.position() * axis.scale)

    def _cmd_md(self, axis: _EmulatedAxis, query: bool, param: str) -> str:
        """MD?: motion done, 1 when stopped, 0 while moving."""
        return "0" if axis.moving() else "1"

    def _cmd_mo(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """MO: motor on; MO? 1 if on, 0 if off."""
        if query:
            return "1" if axis.motor_on else "0"
        if self._estop_open:
            raise _Fail(4)
        axis.motor_on = True
        return None

    def _cmd_mf(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """MF: motor off (motion ends where it is); MF? as MO?."""
        if query:
            return "1" if axis.motor_on else "0"
        axis.motion.abort()
        axis.homing = False
        axis.motor_on = False
        return None

    def _cmd_or(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """OR[mode]: home search (modes 0..6); the stage finds home (0, or the nearest
        limit if 0 is outside its travel) and is homed."""
        if query:
            raise _Fail(6)
        mode = self._number(param, required=False)
        if mode is not None and (mode != int(mode) or not 0 <= mode <= 6):
            raise axis.fail(1)
        if not axis.motor_on:
            raise axis.fail(13)
        try:
            if not axis.motion.home_end() <= HORIZON_S:
                raise axis.fail(1)
            axis.motion.home()
        except MotionError:
            raise axis.fail(1) from None
        axis.homing = not self.clock.instant
        return None

    def _cmd_dh(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """DH[pos]: define the current position as home (pos, default 0)."""
        if query:
            raise _Fail(6)
        value = self._number(param, required=False) or 0.0
        if axis.moving():
            raise axis.fail(26)
        try:
            axis.motion.define_position(value / axis.scale)
        except MotionError:
            raise axis.fail(1) from None
        return None

    def _rate(self, axis: _EmulatedAxis, query: bool, param: str, attr: str, top: float,
              over_code: int) -> str | None:
        if query:
            return self._fmt(getattr(axis.motion, attr) * axis.scale)
        value = self._number(param) / axis.scale
        if value <= 0.0:
            raise axis.fail(1)
        if value > top:
            raise axis.fail(over_code)
        setattr(axis.motion, attr, value)
        return None

    def _cmd_va(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """VA: velocity (units/s) of the next move; above VU is error x10."""
        return self._rate(axis, query, param, "speed", axis.max_speed, 10)

    def _cmd_ac(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """AC: acceleration (units/s^2); above AU is error x11."""
        return self._rate(axis, query, param, "accel", axis.max_accel, 11)

    def _cmd_ag(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """AG: deceleration (units/s^2), also used by ST; above AU is error x11."""
        return self._rate(axis, query, param, "decel", axis.max_accel, 11)

    def _limit(self, axis: _EmulatedAxis, query: bool, param: str, side: int) -> str | None:
        lo, hi = axis.motion.limits
        if query:
            return self._fmt((lo, hi)[side] * axis.scale)
        value = self._number(param) / axis.scale
        new = (value, hi) if side == 0 else (lo, value)
        if not (new[0] < new[1] and math.isfinite(value)):
            raise axis.fail(1)
        axis.motion.limits = new
        return None

    def _cmd_sl(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """SL: left (negative) software limit."""
        return self._limit(axis, query, param, 0)

    def _cmd_sr(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """SR: right (positive) software limit."""
        return self._limit(axis, query, param, 1)

    def _cmd_sn(self, axis: _EmulatedAxis, query: bool, param: str) -> str | None:
        """SN: displacement units (7 degree, 8 gradian, 9 rad, 10 mrad, 11 urad here)."""
        if query:
            return str(axis.units)
        code = self._number(param)
        if code not in ANGULAR_UNITS:
            raise axis.fail(1)
        axis.units = int(code)
        return None

    def _targets(self, axis: _EmulatedAxis | None) -> list[_EmulatedAxis]:
        return list(self.axes.values()) if axis is None else [axis]

    def _cmd_st(self, axis: _EmulatedAxis | None, query: bool, param: str) -> str | None:
        """ST: stop with the AG deceleration (no axis number = every axis); stops homing."""
        if query:
            raise _Fail(6)
        for target in self._targets(axis):
            aborted_home = target.homing and target.moving()
            target.motion.stop()
            target.homing = False
            if aborted_home:
                self._log_error(target.number * 100 + 20)
        return None

    def _cmd_ab(self, axis: None, query: bool, param: str) -> str | None:
        """AB: abort motion, every axis stops at once (no deceleration).

        The real unit's further E-stop action depends on its ZE configuration; the
        emulator only stops the axes (motors stay on).
        """
        if query:
            raise _Fail(6)
        for target in self.axes.values():
            target.motion.abort()
            target.homing = False
        return None

    def _cmd_ws(self, axis: _EmulatedAxis | None, query: bool, param: str) -> str | None:
        """WS[ms]: hold the command line until the axis (all axes) stops, then ms more."""
        if query:
            raise _Fail(6)
        delay_s = (self._number(param, required=False) or 0.0) / 1000.0
        if not 0.0 <= delay_s <= HORIZON_S - self.clock.now():
            raise _Fail(7)
        targets = self._targets(axis)
        while any(t.moving() for t in targets) and not self._stopping.is_set():
            time.sleep(0.002)
        real = self.clock.real_seconds(delay_s)
        if 0.0 < real < math.inf:
            self._stopping.wait(min(real, threading.TIMEOUT_MAX))
        else:  # an instant or a frozen clock: only advances move it
            self.clock.advance(delay_s)
        return None

    def _cmd_te(self, axis: None, query: bool, param: str) -> str:
        """TE?: the oldest buffered error code (0 = none); reading removes it."""
        return str(self.errors.popleft()[0]) if self.errors else "0"

    def _cmd_tb(self, axis: None, query: bool, param: str) -> str:
        """TB?: oldest error as "code, timestamp (servo ticks), MESSAGE"; reading removes it."""
        code, stamp = self.errors.popleft() if self.errors else (0, self._ticks())
        if code >= 100:
            text = AXIS_ERRORS.get(code % 100, "UNKNOWN ERROR")
        else:
            text = GENERAL_ERRORS.get(code, "UNKNOWN ERROR")
        return f"{code}, {stamp}, {text}"

    def _cmd_ve(self, axis: None, query: bool, param: str) -> str:
        """VE?: controller model and firmware version."""
        return self.version
