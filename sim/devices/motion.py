"""Virtual clock and trapezoidal-profile axis shared by every emulated motion device.

A `VirtualClock` maps real time to virtual time (scaled, or infinitely fast: moves
complete at once but the clock still advances by their duration); a `TrapezoidAxis`
plans accelerate / cruise / decelerate moves on it and reports the actual position.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass


class MotionError(ValueError):
    """A motion request the axis refuses; emulators map it to the device's own error code."""


class LimitError(MotionError):
    """A target outside the software travel limits (`side` is "positive" or "negative")."""

    def __init__(self, target: float, limits: tuple[float, float]):
        self.target, self.limits = target, limits
        self.side = "positive" if target > limits[1] else "negative"
        super().__init__(
            f"target {target:g} outside the {self.side} software limit "
            f"(limits {limits[0]:g} .. {limits[1]:g})"
        )


class VirtualClock:
    """Virtual seconds = offset + real seconds * time_scale (0 = only `advance` moves it).

    With time_scale = math.inf, real time does not count; a move is over at once, and the
    clock reaches its end (`due`) when it is next read, so a move "takes" its full duration
    and moves started together (at `start_time`) end together, at the later end.

    `run_time` counts the devices' modelled time: what the motions, waits and readings asked
    of them last (`busy`, `wait`, `spend`), counted as the instant clock counts them, so that
    at any time scale the same commands give the same times whatever the machine's load (the
    real-time pacing between commands does not count); on an instant or frozen clock it is
    `now`.
    """

    def __init__(self, time_scale: float = 1.0):
        if not (time_scale >= 0.0):
            raise ValueError(f"time_scale must be >= 0 (or inf), got {time_scale!r}")
        self.time_scale = float(time_scale)
        self._lock = threading.Lock()
        self._real0 = time.monotonic()
        self._offset = 0.0
        self._due = 0.0  # instant: the latest end of the motions begun, reached when read
        self._run = 0.0  # a running clock's run_time, and the latest end of what is begun
        self._run_due = 0.0

    @property
    def instant(self) -> bool:
        """True when moves complete at once (infinite time scale)."""
        return math.isinf(self.time_scale)

    def now(self) -> float:
        """Virtual time in seconds since the clock was made (an instant clock first reaches
        the ends of the motions begun)."""
        with self._lock:
            self._reach_due()
            return self._now_locked()

    def start_time(self) -> float:
        """When a device acting now starts: now, except that on an instant clock the motions
        begun and not yet read have not taken their time (axes started together overlap)."""
        with self._lock:
            return self._now_locked()

    def due(self, t: float) -> None:
        """A motion begun on an instant clock ends at t: the clock reaches it when next read."""
        with self._lock:
            self._due = max(self._due, t)

    def _reach_due(self) -> None:
        self._offset = max(self._offset, self._due)

    @property
    def _counted(self) -> bool:
        """Whether run_time is counted apart from now (a running clock)."""
        return not self.instant and self.time_scale > 0.0

    def run_time(self) -> float:
        """The devices' modelled seconds (the class doc): the ends of what was begun reached."""
        if not self._counted:
            return self.now()
        with self._lock:
            self._run = max(self._run, self._run_due)
            return self._run

    def run_start_time(self) -> float:
        """run_time as a device acting now starts: what is begun and not yet read has not
        taken its time (as start_time)."""
        if not self._counted:
            return self.start_time()
        with self._lock:
            return self._run

    def busy(self, duration_s: float) -> None:
        """A device begins something that lasts duration_s (a motion): run_time reaches its
        end when next read (on an instant clock the motion's `due` does that)."""
        if self._counted:
            with self._lock:
                self._run_due = max(self._run_due, self._run + duration_s)

    def _pass(self, seconds: float) -> None:
        """run_time passes by seconds after the ends of what was begun."""
        with self._lock:
            self._run = max(self._run, self._run_due) + seconds

    def wait(self, seconds: float) -> float:
        """Real seconds a wait of `seconds` of the devices' time takes (settling, dwell, a
        recheck): an instant clock is advanced by it and says 0, a running one counts it in
        run_time."""
        if self.instant:
            self.advance(seconds)
            return 0.0
        if self._counted:
            self._pass(seconds)
        return self.real_seconds(seconds)

    def _now_locked(self) -> float:
        if self.instant or self.time_scale == 0.0:
            return self._offset
        return self._offset + (time.monotonic() - self._real0) * self.time_scale

    def advance(self, dt: float) -> float:
        """Jump the clock forward by dt virtual seconds; returns the new time."""
        if not (dt >= 0.0 and math.isfinite(dt)):
            raise ValueError(f"clock can only advance by a finite dt >= 0, got {dt!r}")
        with self._lock:
            self._reach_due()
            self._offset += dt
            return self._now_locked()

    def advance_to(self, t: float) -> float:
        """Jump the clock forward to virtual time t if it is still earlier; returns now."""
        with self._lock:
            self._reach_due()
            now = self._now_locked()
            if t > now:
                # exactly t when only advances move the clock: an end time reached must not
                # fall one rounding short of itself
                self._offset = t if now == self._offset else self._offset + t - now
            return self._now_locked()

    def spend(self, virtual_s: float) -> None:
        """A device is busy for virtual_s virtual seconds (a reading it averages): an instant
        clock advances by it, a running one is waited on for the real seconds it takes, a
        frozen one not at all."""
        if self.instant:
            self.advance(virtual_s)
        elif self._counted and virtual_s > 0.0:
            self._pass(virtual_s)
            time.sleep(self.real_seconds(virtual_s))

    def real_seconds(self, virtual_s: float) -> float:
        """Real seconds that virtual_s virtual seconds take (0 if instant, inf if frozen)."""
        if self.instant:
            return 0.0
        if self.time_scale == 0.0:
            return math.inf
        return virtual_s / self.time_scale


@dataclass(frozen=True)
class _Segment:
    """Constant-acceleration piece of a profile: starts at t0 with p0, v0; lasts dt."""

    t0: float
    dt: float
    p0: float
    v0: float
    a: float

    def at(self, t: float) -> tuple[float, float]:
        """Position and velocity at virtual time t (clamped to the segment)."""
        tau = min(max(t - self.t0, 0.0), self.dt)
        return self.p0 + self.v0 * tau + 0.5 * self.a * tau * tau, self.v0 + self.a * tau

    @property
    def t_end(self) -> float:
        """Virtual time the segment ends."""
        return self.t0 + self.dt


def profile_times(
    distance: float, speed: float, accel: float, decel: float | None = None
) -> tuple[float, float, float]:
    """Accelerating, cruising and decelerating times of a rest-to-rest move over |distance|.

    Full speed is reached when |d| >= v^2/(2a) + v^2/(2b) (b = decel, default a): then
    t_acc = v/a, t_dec = v/b, t_cruise = (|d| - v^2/(2a) - v^2/(2b))/v. Otherwise a
    triangle with peak speed v_p = sqrt(2|d| a b / (a + b)) and no cruise.
    """
    b = accel if decel is None else decel
    d = abs(distance)
    ramps = 0.5 * speed * speed * (1.0 / accel + 1.0 / b)
    if d >= ramps:
        return speed / accel, (d - ramps) / speed, speed / b
    v_peak = math.sqrt(2.0 * d * accel * b / (accel + b))
    return v_peak / accel, 0.0, v_peak / b


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (value > 0.0 and math.isfinite(value)):
        raise MotionError(f"{name} must be a finite number > 0, got {value!r}")
    return value


class TrapezoidAxis:
    """One axis moving rest-to-rest with trapezoidal velocity profiles on a VirtualClock.

    Thread-safe. Positions are in the caller's unit (degrees for rotation stages); decel
    defaults to accel (a symmetric profile); home_position defaults to 0, or to the nearest
    limit when 0 is outside the travel.
    """

    def __init__(
        self,
        clock: VirtualClock,
        speed: float,
        accel: float,
        limits: tuple[float, float] = (-math.inf, math.inf),
        position: float = 0.0,
        decel: float | None = None,
        home_position: float | None = None,
    ):
        lo, hi = float(limits[0]), float(limits[1])
        if not lo < hi:
            raise MotionError(f"limits must be (lo, hi) with lo < hi, got {limits!r}")
        self.clock = clock
        self._speed = _positive("speed", speed)
        self._accel = _positive("accel", accel)
        self._decel = _positive("decel", accel if decel is None else decel)
        self._limits = (lo, hi)
        self._lock = threading.RLock()
        self._segments: list[_Segment] = []
        self._rest = float(position)
        self._homing_done_at: float | None = None
        self._homed = False
        self._home_position = home_position
        self._free_at = 0.0  # on an instant clock: when its last motion ends

    # -- parameters -------------------------------------------------------------
    @property
    def speed(self) -> float:
        """Cruise speed (units/s) used by the next move."""
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        self._speed = _positive("speed", value)

    @property
    def accel(self) -> float:
        """Acceleration (units/s^2) used by the next move."""
        return self._accel

    @accel.setter
    def accel(self, value: float) -> None:
        self._accel = _positive("accel", value)

    @property
    def decel(self) -> float:
        """Deceleration (units/s^2) used by the next move's end and by stop()."""
        return self._decel

    @decel.setter
    def decel(self, value: float) -> None:
        self._decel = _positive("decel", value)

    @property
    def limits(self) -> tuple[float, float]:
        """Software travel limits (lo, hi)."""
        return self._limits

    @limits.setter
    def limits(self, value: tuple[float, float]) -> None:
        lo, hi = float(value[0]), float(value[1])
        if not lo < hi:
            raise MotionError(f"limits must be (lo, hi) with lo < hi, got {value!r}")
        self._limits = (lo, hi)

    @property
    def home_position(self) -> float | None:
        """Where home() ends (None: 0, or the nearest limit when 0 is outside the travel)."""
        return self._home_position

    @home_position.setter
    def home_position(self, value: float | None) -> None:
        self._home_position = None if value is None else float(value)

    def duration(self, distance: float) -> float:
        """Virtual seconds a rest-to-rest move over `distance` takes at the current settings."""
        return sum(profile_times(distance, self._speed, self._accel, self._decel))

    # -- state ------------------------------------------------------------------
    def _now(self) -> float:
        """The time the axis is at: on an instant clock, once its own motions are over (their
        ends are the clock's `due`), so moves of axes started together overlap."""
        if self.clock.instant:
            return max(self.clock.start_time(), self._free_at)
        return self.clock.now()

    def _state(self, t: float) -> tuple[float, float]:
        """Position and velocity at time t; drops finished segments."""
        while self._segments and self._segments[0].t_end <= t:
            self._segments.pop(0)
        if not self._segments:
            return self._rest, 0.0
        return self._segments[0].at(t)

    def _settle_homing(self, t: float) -> None:
        if self._homing_done_at is not None and t >= self._homing_done_at:
            self._homing_done_at = None
            self._homed = True

    def position(self) -> float:
        """Actual position at clock.now()."""
        with self._lock:
            t = self._now()
            self._settle_homing(t)
            return self._state(t)[0]

    def velocity(self) -> float:
        """Actual velocity at clock.now()."""
        with self._lock:
            return self._state(self._now())[1]

    def target(self) -> float:
        """Where the current motion ends (the position when at rest)."""
        with self._lock:
            self._state(self._now())
            if not self._segments:
                return self._rest
            last = self._segments[-1]
            return last.at(last.t_end)[0]

    def is_moving(self) -> bool:
        """True while a move, stop or home is still under way."""
        with self._lock:
            t = self._now()
            self._settle_homing(t)
            self._state(t)
            return bool(self._segments)

    @property
    def homed(self) -> bool:
        """True once a home() has completed (and no abort interrupted it)."""
        with self._lock:
            self._settle_homing(self._now())
            return self._homed

    # -- commands ---------------------------------------------------------------
    def move_to(self, target: float) -> float:
        """Start an absolute move; returns its end time. A moving axis first decelerates.

        Raises LimitError (target outside limits) or MotionError (target not finite).
        """
        target = self._reachable(target)
        with self._lock:
            self._homing_done_at = None
            return self._plan(target)

    def _reachable(self, target: float) -> float:
        """`target` as a float; raises MotionError if not finite, LimitError outside limits."""
        target = float(target)
        if not math.isfinite(target):
            raise MotionError(f"target must be finite, got {target!r}")
        lo, hi = self._limits
        if not lo <= target <= hi:
            raise LimitError(target, self._limits)
        return target

    def move_by(self, delta: float) -> float:
        """Start a relative move from the current target; returns its end time."""
        return self.move_to(self.target() + float(delta))

    def _plan(self, target: float) -> float:
        t = self._now()
        self._segments, self._rest = self._profile(t, target)
        t_end = self._finish()
        self.clock.busy(t_end - t)
        return t_end

    def _profile(self, t: float, target: float) -> tuple[list[_Segment], float]:
        """Segments of a move to `target` begun at time t (any motion first decelerated to
        rest) and the rest position they end at; changes nothing."""
        t_start, p_start, segments = self._stopping(t)
        dist = target - p_start
        if dist == 0.0:
            return segments, p_start
        sign = math.copysign(1.0, dist)
        t_acc, t_cruise, t_dec = profile_times(dist, self._speed, self._accel, self._decel)
        v_peak = sign * self._accel * t_acc
        p1 = p_start + 0.5 * v_peak * t_acc
        p2 = p1 + v_peak * t_cruise
        segments += [
            _Segment(t_start, t_acc, p_start, 0.0, sign * self._accel),
            _Segment(t_start + t_acc, t_cruise, p1, v_peak, 0.0),
            _Segment(t_start + t_acc + t_cruise, t_dec, p2, v_peak, -sign * self._decel),
        ]
        # at rest exactly on target, no rounding drift
        return [s for s in segments if s.dt > 0.0], target

    def _stopping(self, t: float) -> tuple[float, float, list[_Segment]]:
        """(t_rest, p_rest, segments): a deceleration to rest from the state at time t."""
        p, v = self._state(t)
        if v == 0.0:
            return t, p, []
        seg = _Segment(t, abs(v) / self._decel, p, v, -math.copysign(self._decel, v))
        return seg.t_end, seg.at(seg.t_end)[0], [seg]

    def _decelerate(self, t: float) -> None:
        """Replace any motion by a deceleration to rest from time t."""
        _, self._rest, self._segments = self._stopping(t)

    def move_end(self, target: float) -> float:
        """Virtual time a move_to(target) started now would end (a preview; moves nothing).

        Raises as move_to does.
        """
        target = self._reachable(target)
        with self._lock:
            t = self._now()
            segments, _ = self._profile(t, target)
            return segments[-1].t_end if segments else t

    def home_end(self) -> float:
        """Virtual time a home() started now would end (a preview; moves nothing)."""
        return self.move_end(self._home_target())

    def _finish(self) -> float:
        """End time of the planned motion (on an instant clock the axis is free then, and the
        clock reaches it when next read)."""
        t_end = self._segments[-1].t_end if self._segments else self._now()
        if self.clock.instant:
            self._free_at = t_end
            self.clock.due(t_end)
        return t_end

    def stop(self) -> None:
        """Decelerate to rest at the current acceleration (no-op at rest); cancels homing."""
        with self._lock:
            self._homing_done_at = None
            self._decelerate(self._now())
            self._finish()

    def abort(self) -> None:
        """Stop at once where the axis is now (no deceleration); cancels homing."""
        with self._lock:
            self._homing_done_at = None
            p, _ = self._state(self._now())
            self._segments = []
            self._rest = p

    def define_position(self, position: float) -> None:
        """Redefine the current (resting) position as `position` and mark the axis homed.

        Raises MotionError while moving or for a non-finite value.
        """
        position = float(position)
        if not math.isfinite(position):
            raise MotionError(f"position must be finite, got {position!r}")
        with self._lock:
            if self.is_moving():
                raise MotionError("cannot redefine the position while moving")
            self._rest = position
            self._homing_done_at = None
            self._homed = True

    def _home_target(self) -> float:
        lo, hi = self._limits
        return min(max(0.0, lo), hi) if self._home_position is None else self._home_position

    def home(self) -> float:
        """Move to the home position and set `homed` when it arrives; returns the end time."""
        with self._lock:
            self._homed = False
            t_end = self._plan(self._reachable(self._home_target()))
            self._homing_done_at = t_end
            self._settle_homing(self._now())
            return t_end
