"""Emulated Zaber X-series rotary stages speaking Zaber's ASCII protocol on a pty.

Written from Zaber's ASCII protocol manual (firmware 7: message format, reply fields, reply
flags and rejection reasons, warning flags, checksums, alerts) and the X-series getting
started manual (microsteps). A command is `/[device] [axis] [message id] command [data]
[:CC]` ended by CR, LF or both; every device it addresses (device 0 or none: all of them)
answers one reply `@dd a [id] OK|RJ BUSY|IDLE flag data[:CC]` ended by CR LF, data being the
rejection reason after RJ. Axis 0 means the whole device: a motion command moves, and a
`get` of an axis setting answers for, every axis. `:CC` is the two hex digits of the
longitudinal redundancy check (the two's complement of the byte sum, mod 256) of what lies
between the first character and the colon; replies carry one while comm.checksum is 1. Our
reading of the manual: a command whose checksum does not match is dropped unanswered (its
address cannot be trusted either). Alerts (`!dd a IDLE flag`, comm.alert 1) tell that a
motion ended; this emulator runs only when a request arrives, so an alert goes out just
before the next reply. No command emulated here answers with info messages (`#`).

Every axis is modelled on the X-RSW60A rotary stage: one full motor step turns it 0.015 deg,
so at the default resolution of 64 microsteps per step a position unit (a microstep) is
0.000234375 deg (1,536,000 per turn). Speeds are given as 1.6384 x microsteps/s and
accelerations as 1.6384e-4 x microsteps/s^2 (the manual's units for maxspeed and accel).
Motion runs in degrees on the shared virtual clock (sim.devices.motion) and is reported in
whole microsteps.
"""

from __future__ import annotations

import re
import threading
from collections import Counter
from collections.abc import Callable, Mapping
from functools import partial
from itertools import takewhile

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import LimitError, MotionError, TrapezoidAxis, VirtualClock
from sim.devices.pty_server import PtyDevice, PtyServer

STEP_DEG = 0.015  # X-RSW60A: stage rotation per full motor step
SPEED_UNIT = 1.6384  # maxspeed data per microstep/s
ACCEL_UNIT = 1.6384e-4  # accel data per microstep/s^2
FIRMWARE = "7.38"
DEVICE_ID = 50001  # what `get deviceid` answers by default (the emulator's, not the product's)
SERIAL_BASE = 120000  # device n answers system.serial SERIAL_BASE + n
MAX_AXES = 9

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

_INTEGER = re.compile(r"-?\d+")
_HEX2 = re.compile(r"[0-9A-F]{2}")


class ZaberConfigError(ValueError):
    """An invalid axis table for the emulator (the message names the axis and key)."""


class _Reject(Exception):
    """A command rejected with one of the manual's reasons (answered RJ)."""

    def __init__(self, reason: str):
        self.reason = reason


def lrc(text: str) -> str:
    """The manual's message checksum of `text`, two upper-case hex digits."""
    return f"{-sum(text.encode('ascii')) & 0xFF:02X}"


def _by_priority(flags: list[str]) -> list[str]:
    """Warning flags, faults (F) first, then warnings (W), then notices (N)."""
    return sorted(flags, key=lambda flag: "FWN".index(flag[0]))


def _integer(text: str) -> int:
    if _INTEGER.fullmatch(text) is None:
        raise _Reject("BADDATA")
    return int(text)


class _EmulatedAxis:
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
        self.referenced = bool(cfg["homed"])  # a reference held before any home
        self.fault: str | None = None  # a latched fault flag (F*), cleared by `warnings clear`
        self.interrupted = False  # NI: the last movement command cut another one short
        self.alert_pending = False

    @property
    def microstep_deg(self) -> float:
        """Degrees per position unit at the current resolution."""
        return STEP_DEG / self.resolution

    def data(self, deg: float) -> int:
        """A position in degrees as whole microsteps."""
        return round(deg / self.microstep_deg)

    def speed_data(self, deg_s: float) -> int:
        return round(deg_s / self.microstep_deg * SPEED_UNIT)

    def accel_data(self, deg_s2: float) -> int:
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
        return self.motion.is_moving()

    def warning(self) -> str:
        """The highest-priority flag now (-- for none)."""
        return (self.flags() or ["--"])[0]

    def flags(self) -> list[str]:
        """Every active flag, highest priority first (the `warnings` command's list)."""
        found = [self.fault] if self.fault else []
        if not (self.referenced or self.motion.homed):
            found.append("WR")
        return found + (["NI"] if self.interrupted else [])

    # -- commands (each raises _Reject or returns the reply data) ----------------------
    def check_move(self, target: int) -> None:
        if not self.limit_min <= target <= self.limit_max:
            raise _Reject("BADDATA")

    def start(self, motion: Callable[[], object], alerts: bool) -> None:
        """Begin a movement command: it interrupts (NI) whatever motion was under way."""
        self.interrupted = self.busy()
        try:
            motion()
        except (LimitError, MotionError):
            raise _Reject("BADDATA") from None
        self.alert_pending = alerts

    def move_to(self, target: int, alerts: bool) -> None:
        self.start(lambda: self.motion.move_to(target * self.microstep_deg), alerts)

    def home(self, alerts: bool) -> None:
        self.referenced = False  # the old reference is gone until the new one is found
        self.start(self.motion.home, alerts)

    def get(self, name: str) -> str:
        if name == "pos":
            return str(self.data(self.motion.position()))
        if name in ("maxspeed", "accel", "resolution"):
            return str(getattr(self, name))
        if name in ("limit.min", "limit.max"):
            return str(getattr(self, name.replace(".", "_")))
        raise _Reject("BADCOMMAND")

    def set(self, name: str, value: int) -> None:
        if name == "pos":
            if self.busy():
                raise _Reject("STATUSBUSY")
            self.motion.define_position(value * self.microstep_deg)
            self.referenced = True
        elif name in ("maxspeed", "accel", "limit.min", "limit.max"):
            new = {"maxspeed": self.maxspeed, "accel": self.accel,
                   "limit.min": self.limit_min, "limit.max": self.limit_max, name: value}
            if not (0 < new["maxspeed"] <= self.max_speed and 0 < new["accel"] <= self.max_accel
                    and new["limit.min"] < new["limit.max"]):
                raise _Reject("BADDATA")
            self._use(*new.values())
        else:
            raise _Reject("BADCOMMAND")  # unknown, or read-only (resolution)


class _EmulatedDevice:
    """One device on the chain: its address, axes and device-scope settings."""

    def __init__(self, address: int, axes: dict[int, _EmulatedAxis], device_id: int):
        self.address, self.axes = address, axes
        self.settings = {"deviceid": device_id, "system.serial": SERIAL_BASE + address,
                         "version": FIRMWARE, "system.axiscount": len(axes),
                         "comm.alert": 0, "comm.checksum": 0}

    def status(self, axis: int) -> tuple[str, str]:
        """BUSY/IDLE and the warning flag of an axis, or of the device (axis 0): busy if any
        axis is, and the highest-priority flag of any axis."""
        chosen = [self.axes[axis]] if axis else list(self.axes.values())
        flags = _by_priority([w for a in chosen if (w := a.warning()) != "--"])
        return ("BUSY" if any(a.busy() for a in chosen) else "IDLE"), (flags + ["--"])[0]

    @property
    def alerting(self) -> bool:
        """comm.alert is on: motions that end send an alert."""
        return bool(self.settings["comm.alert"])

    def alerts(self) -> list[str]:
        """Alerts of the axes whose motion has ended since it started (comm.alert 1)."""
        found = []
        for number, axis in self.axes.items():
            if axis.alert_pending and not axis.busy():
                axis.alert_pending = False
                found.append(self.message("!", f"{number} IDLE {axis.warning()}"))
        return found

    def message(self, kind: str, body: str) -> str:
        """A message of this device: kind, address, body, and the checksum if it is on."""
        text = f"{self.address:02d} {body}"
        return kind + (f"{text}:{lrc(text)}" if self.settings["comm.checksum"] else text)


class ZaberEmulator(PtyDevice):
    """A chain of Zaber X-series devices with rotary axes on a virtual clock, served on a pty.

    axes: {axis number: table} for the device at `address`, or {(device address, axis
    number): table} for a daisy chain of several devices; tables use the keys of AXIS_KEYS
    (degrees). faults: injected on replies; seed: mixed into the fault RNG seed. `axes` of
    the emulator maps the same keys to the emulated axes (`.motion` is the TrapezoidAxis the
    optical bench reads).
    """

    protocol = "zaber"

    def __init__(
        self,
        clock: VirtualClock | None = None,
        axes: Mapping[int | tuple[int, int], Mapping[str, object]] | None = None,
        faults: FaultSpec | None = None,
        seed: int = 0,
        address: int = 1,
        device_id: int = DEVICE_ID,
    ):
        self.clock = clock or VirtualClock(1.0)
        tables = axes if axes is not None else {1: {}}
        if not tables:
            raise ZaberConfigError("zaber: at least one axis is needed")
        chain: dict[int, dict[int, _EmulatedAxis]] = {}
        self.axes: dict[int | tuple[int, int], _EmulatedAxis] = {}
        for key, table in tables.items():
            dev, number = key if isinstance(key, tuple) else (address, key)
            if not all(isinstance(n, int) and not isinstance(n, bool) for n in (dev, number)) \
                    or not (1 <= dev <= 99 and 1 <= number <= MAX_AXES):
                raise ZaberConfigError(f"zaber: axis {key!r}: device addresses are 1..99 and "
                                       f"axis numbers 1..{MAX_AXES}")
            axis = _EmulatedAxis(f"zaber device {dev} axis {number}", self.clock, table)
            chain.setdefault(dev, {})[number] = self.axes[key] = axis
        for dev, numbered in chain.items():
            if sorted(numbered) != list(range(1, len(numbered) + 1)):
                raise ZaberConfigError(f"zaber device {dev}: axes must be numbered 1..n, got "
                                       f"{sorted(numbered)}")
        self.devices = {dev: _EmulatedDevice(dev, dict(sorted(numbered.items())), device_id)
                        for dev, numbered in sorted(chain.items())}
        self.received: Counter[str] = Counter()  # commands, by name ("move abs", "home")
        self._lock = threading.RLock()
        self._server = PtyServer(
            self.handle_line, terminators=b"\r\n", max_line=256,
            faults=FaultInjector(faults, seed=seed), reply_tail=2, name="zaber",
        )

    def axis_position_deg(self, key: int | tuple[int, int]) -> float:
        """Actual position of an axis now, degrees (for the optical bench)."""
        return self.axes[key].motion.position()

    def raise_fault(self, key: int | tuple[int, int], flag: str = "FS") -> None:
        """Make an axis stop itself and latch a fault flag (FS: stalled and stopped), as a
        stage that has detected a stall does; `warnings clear` acknowledges it."""
        if not (len(flag) == 2 and flag.startswith("F") and flag.isupper()):
            raise ValueError(f"a fault flag is F and a letter, got {flag!r}")
        with self._lock:
            axis = self.axes[key]
            axis.motion.abort()
            axis.fault = flag

    # -- protocol ----------------------------------------------------------------------
    def handle_line(self, line: bytes) -> bytes | None:
        """Answer one command line: the reply of every device it addresses (CR LF each),
        after any alert due; None for a line that is no command or not for this chain."""
        text = line.decode("ascii", errors="replace").strip()
        if not text.startswith("/"):
            return None
        body = text[1:]
        if ":" in body:
            body, cc = body.rsplit(":", 1)
            if _HEX2.fullmatch(cc) is None or lrc(body) != cc:
                return None
        words = body.split()
        numbers: list[int] = []
        while words and len(numbers) < 3 and words[0].isdigit():
            numbers.append(int(words.pop(0)))
        address, axis = (numbers + [0, 0])[:2]
        message_id = numbers[2] if len(numbers) == 3 else None
        bad_id = message_id is not None and message_id > 99
        if bad_id:
            message_id = None  # rejected, and not echoed
        with self._lock:
            targets = list(self.devices.values()) if address == 0 else \
                [self.devices[address]] if address in self.devices else []
            out = [alert for dev in targets for alert in dev.alerts()]
            for dev in targets:
                status_axis = axis if 0 < axis <= len(dev.axes) else 0
                # a query's status is taken before its data: the clock runs on between the two,
                # and an IDLE read first guarantees the position read next is the final one
                early = dev.status(status_axis) if (words or [""])[0] in _QUERIES else None
                try:
                    if bad_id:
                        raise _Reject("BADMESSAGEID")
                    flag, data = "OK", self._execute(dev, axis, words)
                except _Reject as rejected:
                    flag, data = "RJ", rejected.reason
                status, warning = early or dev.status(status_axis)
                head = f"{axis}" if message_id is None else f"{axis} {message_id:02d}"
                out.append(dev.message("@", f"{head} {flag} {status} {warning} {data}"))
        return "".join(f"{msg}\r\n" for msg in out).encode("ascii") if out else None

    def _execute(self, dev: _EmulatedDevice, axis: int, words: list[str]) -> str:
        """Run one command on a device (axis 0: the whole device); returns the reply data."""
        if axis > len(dev.axes):
            raise _Reject("BADAXIS")
        chosen = [dev.axes[axis]] if axis else list(dev.axes.values())
        self.received[" ".join(takewhile(lambda w: not _INTEGER.fullmatch(w), words[:2]))] += 1
        handler = _COMMANDS.get(words[0] if words else "")
        if handler is None:
            raise _Reject("BADCOMMAND")
        return handler(self, dev, axis, chosen, words[1:])

    def _status(self, dev, axis, chosen, args: list[str]) -> str:
        """An empty command: only the reply's status and flag matter."""
        return "0"

    def _move(self, dev, axis, chosen, args: list[str]) -> str:
        """move abs N | move rel N | move min | move max (every axis when axis is 0)."""
        kind, values = (args[0], args[1:]) if args else ("", [])
        if kind in ("abs", "rel") and len(values) == 1:
            n = _integer(values[0])
            targets = [n if kind == "abs" else a.data(a.motion.position()) + n for a in chosen]
        elif kind in ("min", "max") and not values:
            targets = [a.limit_min if kind == "min" else a.limit_max for a in chosen]
        else:
            raise _Reject("BADCOMMAND" if kind not in ("abs", "rel", "min", "max")
                          else "BADDATA")
        for a, target in zip(chosen, targets, strict=True):
            a.check_move(target)
        for a, target in zip(chosen, targets, strict=True):
            a.move_to(target, dev.alerting)
        return "0"

    def _home(self, dev, axis, chosen, args: list[str]) -> str:
        """home: find the home position (0, or the nearest limit) and take it as reference."""
        if args:
            raise _Reject("BADDATA")
        for a in chosen:
            a.home(dev.alerting)
        return "0"

    def _halt(self, dev, axis, chosen, args: list[str], how: str) -> str:
        """stop (how="stop"): decelerate to rest, a home it cuts short leaving no reference;
        estop (how="abort"): stop at once, without deceleration."""
        if args:
            raise _Reject("BADDATA")
        for a in chosen:
            a.start(getattr(a.motion, how), dev.alerting and a.busy())
        return "0"

    def _warnings(self, dev, axis, chosen, args: list[str]) -> str:
        """warnings [clear]: the count and list of active flags; clear acknowledges latched
        faults and NI (WR stays until the axis is homed or its position set)."""
        if args not in ([], ["clear"]):
            raise _Reject("BADDATA")
        flags = _by_priority(list(dict.fromkeys(f for a in chosen for f in a.flags())))
        if args:
            for a in chosen:
                a.fault, a.interrupted = None, False
        return " ".join([f"{len(flags):02d}", *flags])

    def _get(self, dev, axis, chosen, args: list[str]) -> str:
        """get SETTING: a device setting (axis 0 only), or an axis setting for each axis."""
        if len(args) != 1:
            raise _Reject("BADDATA" if args else "BADCOMMAND")
        if args[0] in dev.settings:
            if axis:
                raise _Reject("DEVICEONLY")
            return str(dev.settings[args[0]])
        return " ".join(a.get(args[0]) for a in chosen)

    def _set(self, dev, axis, chosen, args: list[str]) -> str:
        """set SETTING VALUE: comm.alert / comm.checksum (0 or 1), or an axis setting."""
        if len(args) != 2:
            raise _Reject("BADDATA" if args else "BADCOMMAND")
        name, value = args[0], _integer(args[1])
        if name in dev.settings:
            if axis:
                raise _Reject("DEVICEONLY")
            if not name.startswith("comm."):
                raise _Reject("BADCOMMAND")  # read-only
            if value not in (0, 1):
                raise _Reject("BADDATA")
            dev.settings[name] = value
            return "0"
        for a in chosen:
            a.get(name)  # an unknown setting is rejected before any axis changes
        for a in chosen:
            a.set(name, value)
        return "0"


#: commands that only read: their reply's status comes from the moment before their data
_QUERIES = {"", "get"}

_COMMANDS = {
    "": ZaberEmulator._status, "move": ZaberEmulator._move, "home": ZaberEmulator._home,
    "stop": partial(ZaberEmulator._halt, how="stop"),
    "estop": partial(ZaberEmulator._halt, how="abort"),
    "warnings": ZaberEmulator._warnings, "get": ZaberEmulator._get, "set": ZaberEmulator._set,
}
