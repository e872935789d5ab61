"""The ESP301 commands the emulator implements, one handler each (ESP301 user's manual
EDH0235En1030, section 3.7): a mixin of `EspEmulator`, which parses lines and dispatches.

Each handler takes (axis or None, query flag, parameter text) and returns the reply text or
None; a failure raises `Fail(code)` for the error buffer, which is kept here too (TE?, TB?,
with the manual's error messages). Positions and rates are kept in degrees and shown in the
axis's SN units, numbers with 5 decimals.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from collections.abc import Callable

from sim.devices.esp_axis import (
    ANGULAR_UNITS,
    LARGEST,
    STORED_SETTINGS,
    EmulatedAxis,
    Fail,
    StoredSetting,
)
from sim.devices.motion import LimitError, MotionError, VirtualClock

SERVO_TICK_S = 400e-6  # TB? timestamps count servo interrupts (400 us by default)
# A wait or motion that would end later than this after power-up is a parameter out of range:
# TB?'s timestamp then stays an exact integer count of servo ticks (2**53, about 114000 years).
HORIZON_S = 2.0**53 * SERVO_TICK_S
MAX_WAIT_MS = 60000.0  # WT (and the manual's WS delay): 0 to 60000 ms
POLL_S = 0.002  # real seconds between looks at the clock while a wait holds the line

# General errors (ESP301 manual, Appendix A "Error messages"), the ones this emulator raises.
GENERAL_ERRORS = {
    0: "NO ERROR DETECTED",
    4: "EMERGENCY STOP ACTIVATED",
    6: "COMMAND DOES NOT EXIST",
    7: "PARAMETER OUT OF RANGE",
    9: "AXIS NUMBER OUT OF RANGE",
    27: "COMMAND NOT ALLOWED",
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

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_HEX = re.compile(r"([0-9A-F]+)H")


def parse_number(param: str, required: bool = True) -> float | None:
    """A command's numeric parameter: 38 when missing (if required), 7 when not a finite
    decimal number."""
    if not param:
        if required:
            raise Fail(38)
        return None
    if _NUMBER.fullmatch(param) is None:
        raise Fail(7)
    value = float(param)
    if not math.isfinite(value):
        raise Fail(7)
    return value


def fmt(value: float) -> str:
    """A number as the controller answers it (5 decimals)."""
    return f"{value:.5f}"


def _parse_setting(kind: str, param: str) -> float:
    """A stored setting's new value: hex words as `0FFFFH` or a decimal integer."""
    if kind == "hex" and (match := _HEX.fullmatch(param)) is not None:
        return float(int(match.group(1), 16))
    return parse_number(param)  # type: ignore[return-value]


def _show_setting(kind: str, value: float) -> str:
    if kind == "hex":
        return f"{int(value):X}H"
    return str(int(value)) if kind == "int" else fmt(value)


class EspCommands:
    """Command handlers of the emulated ESP301 (state lives in `EspEmulator`)."""

    axes: dict[int, EmulatedAxis]
    clock: VirtualClock
    version: str
    _stopping: threading.Event
    _estop_open: bool
    errors: deque[tuple[int, int]]  # the error buffer: (code, timestamp in servo ticks)

    def handler(self, cmd: str) -> Callable[..., str | None] | None:
        """The handler of mnemonic `cmd` (a stored setting's included), or None."""
        method = getattr(self, f"_cmd_{cmd.lower()}", None)
        if method is not None:
            return method
        if cmd in STORED_SETTINGS:
            return lambda axis, query, param: self._stored(cmd, axis, query, param)
        return None

    # -- error buffer -------------------------------------------------------------
    def _ticks(self, at_s: float | None = None) -> int:
        return int((self.clock.now() if at_s is None else at_s) / SERVO_TICK_S)

    def _log_error(self, code: int) -> None:
        self.errors.append((code, self._ticks()))

    def _pop_error(self) -> tuple[int, int | None]:
        """The oldest buffered (code, timestamp), removed; (0, None) when there is none."""
        return self.errors.popleft() if self.errors else (0, None)

    @staticmethod
    def _error_text(code: int) -> str:
        if code >= 100:
            return AXIS_ERRORS.get(code % 100, "UNKNOWN ERROR")
        return GENERAL_ERRORS.get(code, "UNKNOWN ERROR")

    # -- helpers ------------------------------------------------------------------
    def _targets(self, axis: EmulatedAxis | None) -> list[EmulatedAxis]:
        return list(self.axes.values()) if axis is None else [axis]

    def _hold(self, done: Callable[[], bool]) -> None:
        """Hold the command line (as the controller does) until `done()` or the emulator stops."""
        while not done() and not self._stopping.is_set():
            time.sleep(POLL_S)

    def _pause(self, delay_s: float) -> None:
        """Let `delay_s` virtual seconds pass before the next command runs."""
        real = self.clock.wait(delay_s)  # an instant clock advanced by it, 0
        if 0.0 < real < math.inf:
            self._stopping.wait(min(real, threading.TIMEOUT_MAX))
        elif real == math.inf:  # a frozen clock: only advances move it
            self.clock.advance(delay_s)

    def _move(self, axis: EmulatedAxis, target_deg: float) -> None:
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

    # -- motion ---------------------------------------------------------------------
    def _cmd_pa(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """PA: move to absolute position; PA? the target (desired) position."""
        if query:
            return fmt(axis.motion.target() * axis.scale)
        self._move(axis, parse_number(param) / axis.scale)
        return None

    def _cmd_pr(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """PR: move relative to the current target; PR? the target position."""
        if query:
            return fmt(axis.motion.target() * axis.scale)
        self._move(axis, axis.motion.target() + parse_number(param) / axis.scale)
        return None

    def _cmd_mv(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """MV+ / MV-: move at VA towards that side until ST, AB or the software limit there;
        MV? as MD? (0 while moving)."""
        if query:
            return self._cmd_md(axis, True, "")
        if param not in ("+", "-"):
            raise axis.fail(1) if param else Fail(38)
        lo, hi = axis.motion.limits
        self._move(axis, hi if param == "+" else lo)
        return None

    def _cmd_st(self, axis: EmulatedAxis | None, query: bool, param: str) -> str | None:
        """ST: stop with the AG deceleration (no axis number = every axis); stops homing."""
        if query:
            raise Fail(6)
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
            raise Fail(6)
        for target in self.axes.values():
            target.motion.abort()
            target.homing = False
        return None

    def _cmd_or(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """OR[mode]: home search (modes 0..6, default OM) at the OH speed; the stage ends at
        the SH preset (or the nearest limit if SH is outside its travel)."""
        if query:
            raise Fail(6)
        mode = parse_number(param, required=False)
        if mode is not None and (mode != int(mode) or not 0 <= mode <= 6):
            raise axis.fail(1)
        if not axis.motor_on:
            raise axis.fail(13)
        speed = axis.motion.speed
        axis.motion.speed = axis.settings["OH"]
        axis.motion.home_position = axis.home_target()
        try:
            if not axis.motion.home_end() <= HORIZON_S:
                raise axis.fail(1)
            axis.motion.home()
        except MotionError:
            raise axis.fail(1) from None
        finally:
            axis.motion.speed = speed
        axis.homing = not self.clock.instant
        return None

    def _cmd_dh(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """DH[pos]: define the current position as home (pos, default 0); DH? that value."""
        if query:
            return fmt(axis.home_value * axis.scale)
        value = (parse_number(param, required=False) or 0.0) / axis.scale
        if axis.moving():
            raise axis.fail(26)
        try:
            axis.motion.define_position(value)
        except MotionError:
            raise axis.fail(1) from None
        axis.home_value = value
        return None

    def _cmd_sh(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """SH: home preset position, where the next home search ends (within the limits)."""
        if query:
            return fmt(axis.home_preset * axis.scale)
        value = parse_number(param) / axis.scale
        lo, hi = axis.motion.limits
        if not lo <= value <= hi:
            raise axis.fail(1)
        axis.home_preset = value
        return None

    # -- waits ----------------------------------------------------------------------
    def _cmd_ws(self, axis: EmulatedAxis | None, query: bool, param: str) -> str | None:
        """WS[ms]: hold the command line until the axis (all axes) stops, then ms more."""
        if query:
            raise Fail(6)
        delay_s = (parse_number(param, required=False) or 0.0) / 1000.0
        if not 0.0 <= delay_s <= HORIZON_S - self.clock.now():
            raise Fail(7)
        targets = self._targets(axis)
        self._hold(lambda: not any(t.moving() for t in targets))
        self._pause(delay_s)
        return None

    def _cmd_wp(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """WP x: hold the command line until the axis crosses x, which must lie between its
        position and the end of its motion (else x01)."""
        if query:
            raise Fail(6)
        mark = parse_number(param) / axis.scale
        start, end = axis.motion.position(), axis.motion.target()
        if not min(start, end) <= mark <= max(start, end):
            raise axis.fail(1)
        side = math.copysign(1.0, end - start)
        self._hold(lambda: (axis.motion.position() - mark) * side >= 0.0 or not axis.moving())
        return None

    def _cmd_wt(self, axis: None, query: bool, param: str) -> str | None:
        """WT ms: hold the command line for ms (0 to 60000) of virtual time."""
        if query:
            raise Fail(6)
        delay_ms = parse_number(param, required=False) or 0.0
        if not 0.0 <= delay_ms <= MAX_WAIT_MS:
            raise Fail(7)
        self._pause(delay_ms / 1000.0)
        return None

    # -- status ---------------------------------------------------------------------
    def _cmd_tp(self, axis: EmulatedAxis, query: bool, param: str) -> str:
        """TP / TP?: actual position."""
        return fmt(axis.motion.position() * axis.scale)

    def _cmd_dp(self, axis: EmulatedAxis, query: bool, param: str) -> str:
        """DP?: desired (target) position: where the current motion ends."""
        return fmt(axis.motion.target() * axis.scale)

    def _cmd_dv(self, axis: EmulatedAxis, query: bool, param: str) -> str:
        """DV / DV?: desired (profile) velocity now, signed."""
        return fmt(axis.motion.velocity() * axis.scale)

    def _cmd_tv(self, axis: EmulatedAxis, query: bool, param: str) -> str:
        """TV / TV?: actual velocity (the emulated servo follows its profile exactly)."""
        return self._cmd_dv(axis, query, param)

    def _cmd_md(self, axis: EmulatedAxis, query: bool, param: str) -> str:
        """MD?: motion done, 1 when stopped, 0 while moving."""
        return "0" if axis.moving() else "1"

    def _cmd_id(self, axis: EmulatedAxis, query: bool, param: str) -> str:
        """ID?: stage model and serial number; writing a custom ID is not emulated (27)."""
        if not query:
            raise Fail(27)
        return axis.stage_id

    def _cmd_te(self, axis: None, query: bool, param: str) -> str:
        """TE?: the oldest buffered error code (0 = none); reading removes it."""
        return str(self._pop_error()[0])

    def _cmd_tb(self, axis: None, query: bool, param: str) -> str:
        """TB?: oldest error as "code, timestamp (servo ticks), MESSAGE"; reading removes it."""
        code, stamp = self._pop_error()
        if stamp is None:  # no error: the time the command came, without ending the motions
            # begun on an instant clock (which a reading of it does: a TB? after each move
            # would run the axes one after the other)
            stamp = self._ticks(self.clock.start_time())
        return f"{code}, {stamp}, {self._error_text(code)}"

    def _cmd_ve(self, axis: None, query: bool, param: str) -> str:
        """VE?: controller model and firmware version."""
        return self.version

    # -- motor and settings -----------------------------------------------------------
    def _cmd_mo(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """MO: motor on; MO? 1 if on, 0 if off."""
        if query:
            return "1" if axis.motor_on else "0"
        if self._estop_open:
            raise Fail(4)
        axis.motor_on = True
        return None

    def _cmd_mf(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """MF: motor off (motion ends where it is); MF? as MO?."""
        if query:
            return "1" if axis.motor_on else "0"
        axis.motion.abort()
        axis.homing = False
        axis.motor_on = False
        return None

    def _rate(self, axis: EmulatedAxis, query: bool, param: str, attr: str, top: float,
              over_code: int) -> str | None:
        if query:
            return fmt(getattr(axis.motion, attr) * axis.scale)
        value = parse_number(param) / axis.scale
        if value <= 0.0:
            raise axis.fail(1)
        if value > top:
            raise axis.fail(over_code)
        setattr(axis.motion, attr, value)
        return None

    def _cmd_va(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """VA: velocity (units/s) of the next move; above VU is error x10."""
        return self._rate(axis, query, param, "speed", axis.max_speed, 10)

    def _cmd_ac(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """AC: acceleration (units/s^2); above AU is error x11."""
        return self._rate(axis, query, param, "accel", axis.max_accel, 11)

    def _cmd_ag(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """AG: deceleration (units/s^2), also used by ST; above AU is error x11."""
        return self._rate(axis, query, param, "decel", axis.max_accel, 11)

    def _maximum(self, axis: EmulatedAxis, query: bool, param: str, attr: str) -> str | None:
        if query:
            return fmt(getattr(axis, attr) * axis.scale)
        value = parse_number(param)
        if not 0.0 < value <= LARGEST:
            raise axis.fail(1)
        setattr(axis, attr, value / axis.scale)
        return None

    def _cmd_vu(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """VU: maximum speed (0 to 2e9 units/s); VA and the jog and home speeds above a new
        VU come down to it."""
        reply = self._maximum(axis, query, param, "max_speed")
        axis.clamp_speeds()
        return reply

    def _cmd_au(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """AU: maximum acceleration and deceleration (0 to 2e9 units/s^2); AC and AG above a
        new AU come down to it."""
        reply = self._maximum(axis, query, param, "max_accel")
        axis.clamp_accels()
        return reply

    def _cmd_sl(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """SL: left (negative) software limit."""
        return self._limit(axis, query, param, 0)

    def _cmd_sr(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """SR: right (positive) software limit."""
        return self._limit(axis, query, param, 1)

    def _limit(self, axis: EmulatedAxis, query: bool, param: str, side: int) -> str | None:
        lo, hi = axis.motion.limits
        if query:
            return fmt((lo, hi)[side] * axis.scale)
        value = parse_number(param) / axis.scale
        new = (value, hi) if side == 0 else (lo, value)
        if not (new[0] < new[1] and math.isfinite(value)):
            raise axis.fail(1)
        axis.motion.limits = new
        return None

    def _cmd_sn(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """SN: displacement units (7 degree, 8 gradian, 9 rad, 10 mrad, 11 urad here)."""
        if query:
            return str(axis.units)
        code = parse_number(param)
        if code not in ANGULAR_UNITS:
            raise axis.fail(1)
        axis.units = int(code)
        return None

    def _cmd_tj(self, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """TJ: trajectory mode 1..6; only 1 (trapezoidal) is emulated, others are 27."""
        reply = self._stored("TJ", axis, query, param)
        if axis.settings["TJ"] != 1:
            axis.settings["TJ"] = 1.0
            raise Fail(27)
        return reply

    def _stored(self, name: str, axis: EmulatedAxis, query: bool, param: str) -> str | None:
        """A stored setting: its value, or a new one inside the manual's range (else x01,
        x10 above VU for a speed)."""
        spec = STORED_SETTINGS[name]
        scale = axis.scale if spec.scaled else 1.0
        if query:
            return _show_setting(spec.kind, axis.settings[name] * scale)
        value = _parse_setting(spec.kind, param)
        low, high = self._bounds(name, spec, axis)
        if spec.kind != "float" and value != int(value):
            raise axis.fail(1)
        if value > high * scale:
            raise axis.fail(10 if spec.high == "VU" else 1)
        if not low * scale <= value:
            raise axis.fail(1)
        axis.settings[name] = value / scale
        return None

    @staticmethod
    def _bounds(name: str, spec: StoredSetting, axis: EmulatedAxis) -> tuple[float, float]:
        """(low, high) of a stored setting, degrees for a scaled one."""
        low = axis.motion.decel if name == "AE" else spec.low
        if spec.high == "VU":
            return low, axis.max_speed
        if name == "BA":  # up to 10000 encoder counts
            return low, spec.high * axis.settings["SU"]  # type: ignore[operator]
        return low, float(spec.high)

    def _accept(self, axis: EmulatedAxis | None, query: bool, param: str) -> None:
        """A command that only makes the controller take up settings it already uses."""
        if query:
            raise Fail(6)

    _cmd_uf = _accept  # UF: update servo filter (the emulated servo is ideal)
    _cmd_qd = _accept  # QD: update the motor driver (nothing to load)
    _cmd_sm = _accept  # SM: save to flash (settings last as long as the emulator runs)
