"""One emulated axis of a Zaber X-series device: its motion in degrees on the virtual clock and
its settings in the ASCII protocol's integer units (firmware 7).

Modelled on the X-RSW60A rotary stage: one full motor step turns it 0.015 deg, so at the
default resolution of 64 microsteps per step a position unit (a microstep) is 0.000234375 deg
(1,536,000 per turn). Speeds are given as 1.6384 x microsteps/s and accelerations as
1.6384e-4 x microsteps/s^2 (the manual's units for maxspeed and accel).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping

from sim.devices.motion import LimitError, MotionError, TrapezoidAxis, VirtualClock

STEP_DEG = 0.015  # X-RSW60A: stage rotation per full motor step
SPEED_UNIT = 1.6384  # maxspeed data per microstep/s
ACCEL_UNIT = 1.6384e-4  # accel data per microstep/s^2

AXIS_KEYS = {
    "limits_deg": (-170.0, 170.0),  # limit.min / limit.max
    "speed_deg_s": 20.0,  # maxspeed
    "accel_deg_s2": 80.0,  # accel
    "position_deg": 0.0,
    "resolution": 64,  # microsteps per full step (read-only here)
    "max_speed_deg_s": 200.0,  # the emulator's ceiling for maxspeed (BADDATA above)
    "max_accel_deg_s2": 2000.0,  # and for accel
    "homed": True,  # powers up with a position reference (False: WR until homed)
}

#: axis settings `get` reads and `set` writes (resolution is read-only here)
WRITABLE_SETTINGS = ("pos", "maxspeed", "accel", "limit.min", "limit.max")
AXIS_SETTINGS = (*WRITABLE_SETTINGS, "resolution")

_INTEGER = re.compile(r"-?\d+")


class ZaberConfigError(ValueError):
    """An invalid axis table for the emulator (the message names the axis and key)."""


class Reject(Exception):
    """A command rejected with one of the manual's reasons (answered RJ)."""

    def __init__(self, reason: str):
        self.reason = reason


def is_integer(word: str) -> bool:
    """True for a word the protocol reads as an integer (an optional sign and digits)."""
    return _INTEGER.fullmatch(word) is not None


def integer(word: str) -> int:
    """A command's integer data; anything else is rejected with BADDATA."""
    if not is_integer(word):
        raise Reject("BADDATA")
    return int(word)


class EmulatedAxis:
    """One axis: its motion in degrees and its settings in the protocol's integer units."""

    def __init__(self, where: str, clock: VirtualClock, table: Mapping[str, object]):
        unknown = sorted(set(table) - set(AXIS_KEYS))
        if unknown:
            raise ZaberConfigError(
                f"{where}: unknown key {unknown[0]!r} (known: {', '.join(AXIS_KEYS)})")
        cfg = {**AXIS_KEYS, **table}

        def number(key: str) -> float:
            value = cfg[key]
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{key} must be a number, got {value!r}")
            return float(value)

        try:
            self.resolution = int(number("resolution"))
            if self.resolution != number("resolution") or self.resolution < 1:
                raise ValueError(f"resolution must be an integer >= 1, got {cfg['resolution']!r}")
            lo, hi = (self.data(float(v)) for v in cfg["limits_deg"])  # type: ignore[union-attr]
            self.max_speed = self.speed_data(number("max_speed_deg_s"))
            self.max_accel = self.accel_data(number("max_accel_deg_s2"))
            speed = self.speed_data(number("speed_deg_s"))
            accel = self.accel_data(number("accel_deg_s2"))
            if not (0 < speed <= self.max_speed and 0 < accel <= self.max_accel):
                raise ValueError("speed/accel must be > 0 and within max_speed/max_accel")
            self.motion = TrapezoidAxis(clock, 1.0, 1.0, (lo * self.microstep_deg,
                                                          hi * self.microstep_deg),
                                        self.data(number("position_deg")) * self.microstep_deg)
        except (TypeError, ValueError) as exc:
            raise ZaberConfigError(f"{where}: {exc}") from None
        self._use(speed, accel, lo, hi)
        self.referenced = bool(cfg["homed"])  # a reference held (powered up with, or set)
        self.homing = False  # a home under way or ended: its end gives the reference
        self.fault: str | None = None  # a latched fault flag (F*), cleared by `warnings clear`
        self.interrupted = False  # NI: the last movement command cut another one short
        self.alert_pending = False  # the motion under way ends in an alert (comm.alert 1)

    @property
    def microstep_deg(self) -> float:
        """Degrees per position unit at the current resolution."""
        return STEP_DEG / self.resolution

    def data(self, deg: float) -> int:
        """A position in degrees as whole microsteps."""
        return round(deg / self.microstep_deg)

    def speed_data(self, deg_s: float) -> int:
        """A speed in deg/s as maxspeed data."""
        return round(deg_s / self.microstep_deg * SPEED_UNIT)

    def accel_data(self, deg_s2: float) -> int:
        """An acceleration in deg/s^2 as accel data."""
        return round(deg_s2 / self.microstep_deg * ACCEL_UNIT)

    def _use(self, maxspeed: int, accel: int, limit_min: int, limit_max: int) -> None:
        """Take these settings (protocol units) and run the motion with them."""
        self.maxspeed, self.accel, self.limit_min, self.limit_max = \
            maxspeed, accel, limit_min, limit_max
        unit = self.microstep_deg
        self.motion.speed = maxspeed / SPEED_UNIT * unit
        self.motion.accel = self.motion.decel = accel / ACCEL_UNIT * unit
        self.motion.limits = (limit_min * unit, limit_max * unit)

    def busy(self) -> bool:
        """BUSY: a move, stop or home is under way."""
        return self.motion.is_moving()

    def warning(self) -> str:
        """The highest-priority flag now (-- for none)."""
        return (self.flags() or ["--"])[0]

    def flags(self) -> list[str]:
        """Every active flag, highest priority first (the `warnings` command's list)."""
        found = [self.fault] if self.fault else []
        if not (self.referenced or (self.homing and self.motion.homed)):
            found.append("WR")
        return found + (["NI"] if self.interrupted else [])

    # -- commands (each raises Reject or returns the reply data) ----------------------
    def check_move(self, target: int) -> None:
        """BADDATA for a target outside limit.min .. limit.max."""
        if not self.limit_min <= target <= self.limit_max:
            raise Reject("BADDATA")

    def start(self, motion: Callable[[], object], alerts: bool) -> None:
        """Begin a movement command: it interrupts (NI) whatever motion was under way, and
        ends in an alert when `alerts` (comm.alert 1)."""
        self.interrupted = self.busy()
        try:
            motion()
        except (LimitError, MotionError):
            raise Reject("BADDATA") from None
        self.alert_pending = alerts

    def move_to(self, target: int, alerts: bool) -> None:
        """Start a move to `target` microsteps."""
        self.start(lambda: self.motion.move_to(target * self.microstep_deg), alerts)

    def home(self, alerts: bool) -> None:
        """Start a home search; the old reference is gone until it ends."""
        self.referenced, self.homing = False, True
        self.start(self.motion.home, alerts)

    def reset(self) -> None:
        """What `system reset` leaves of the axis: stopped where it is, with no reference
        (WR) and no latched flag, as after power-up."""
        self.motion.abort()
        self.referenced = self.homing = self.interrupted = self.alert_pending = False
        self.fault = None

    def get(self, name: str) -> str:
        """The value of an axis setting (BADCOMMAND for one this axis does not have)."""
        if name == "pos":
            return str(self.data(self.motion.position()))
        if name in AXIS_SETTINGS:
            return str(getattr(self, name.replace(".", "_")))
        raise Reject("BADCOMMAND")

    def set(self, name: str, value: int) -> None:
        """Write an axis setting: BADCOMMAND for an unknown or read-only one, BADDATA for a
        value out of range, STATUSBUSY for `pos` while moving."""
        if name == "pos":
            if self.busy():
                raise Reject("STATUSBUSY")
            self.motion.define_position(value * self.microstep_deg)
            self.referenced = True
        elif name in WRITABLE_SETTINGS:
            new = {"maxspeed": self.maxspeed, "accel": self.accel,
                   "limit.min": self.limit_min, "limit.max": self.limit_max, name: value}
            if not (0 < new["maxspeed"] <= self.max_speed and 0 < new["accel"] <= self.max_accel
                    and new["limit.min"] < new["limit.max"]):
                raise Reject("BADDATA")
            self._use(*new.values())
        else:
            raise Reject("BADCOMMAND")
