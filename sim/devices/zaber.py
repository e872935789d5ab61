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
address cannot be trusted either). While comm.alert is 1 (0 at power-up, as Zaber's devices
ship) a motion that ends sends an alert `!dd a IDLE flag[:CC]` for each axis it moved, when
it ends (sim.devices.zaber_alerts). No command emulated here answers with info messages (`#`).

The axes (sim.devices.zaber_axis) are modelled on the X-RSW60A; the device-scope settings a
client reads while it detects devices are in sim.devices.zaber_device. Motion runs in
degrees on the shared virtual clock (sim.devices.motion) and is reported in whole
microsteps.
"""

from __future__ import annotations

import math
import re
import threading
from collections import Counter
from collections.abc import Mapping
from functools import partial
from itertools import takewhile

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock
from sim.devices.pty_server import PtyDevice
from sim.devices.zaber_alerts import AlertingPtyServer
from sim.devices.zaber_axis import (
    EmulatedAxis,
    Reject,
    ZaberConfigError,
    integer,
    is_integer,
)
from sim.devices.zaber_device import (
    DEVICE_ID,
    FIRMWARE,
    IDENTITY_CHECKS,
    EmulatedDevice,
    by_priority,
    lrc,
)

__all__ = ["MAX_AXES", "ZaberConfigError", "ZaberEmulator", "lrc"]

MAX_AXES = 9

_HEX2 = re.compile(r"[0-9A-F]{2}")


class ZaberEmulator(PtyDevice):
    """A chain of Zaber X-series devices with rotary axes on a virtual clock, served on a pty.

    axes: {axis number: table} for the device at `address`, or {(device address, axis
    number): table} for a daisy chain of several devices; tables use the keys of
    sim.devices.zaber_axis.AXIS_KEYS (degrees). faults: injected on replies and alerts; seed:
    mixed into the fault RNG seed. device_id and firmware: what `get deviceid` and
    `get version` answer (the product's identity); alerts: comm.alert at power-up (a device
    whose setting was saved on); each checked (zaber_device.IDENTITY_CHECKS), ZaberConfigError
    naming the one that is wrong. `axes` of the emulator maps the same keys to the emulated
    axes (`.motion` is the TrapezoidAxis the optical bench reads).
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
        firmware: str = FIRMWARE,
        alerts: bool = False,
    ):
        for key, value in (("device_id", device_id), ("firmware", firmware), ("alerts", alerts)):
            problem = IDENTITY_CHECKS[key](value)
            if problem is not None:
                raise ZaberConfigError(f"zaber: {key}: {problem}")
        self.clock = clock or VirtualClock(1.0)
        tables = axes if axes is not None else {1: {}}
        if not tables:
            raise ZaberConfigError("zaber: at least one axis is needed")
        chain: dict[int, dict[int, EmulatedAxis]] = {}
        self.axes: dict[int | tuple[int, int], EmulatedAxis] = {}
        for key, table in tables.items():
            dev, number = key if isinstance(key, tuple) else (address, key)
            if not all(isinstance(n, int) and not isinstance(n, bool) for n in (dev, number)) \
                    or not (1 <= dev <= 99 and 1 <= number <= MAX_AXES):
                raise ZaberConfigError(f"zaber: axis {key!r}: device addresses are 1..99 and "
                                       f"axis numbers 1..{MAX_AXES}")
            axis = EmulatedAxis(f"zaber device {dev} axis {number}", self.clock, table)
            chain.setdefault(dev, {})[number] = self.axes[key] = axis
        for dev, numbered in chain.items():
            if sorted(numbered) != list(range(1, len(numbered) + 1)):
                raise ZaberConfigError(f"zaber device {dev}: axes must be numbered 1..n, got "
                                       f"{sorted(numbered)}")
        self.devices = {dev: EmulatedDevice(dev, dict(sorted(numbered.items())), device_id,
                                            firmware, alerts)
                        for dev, numbered in sorted(chain.items())}
        self.received: Counter[str] = Counter()  # commands, by name ("move abs", "home")
        self._lock = threading.RLock()
        self._server = AlertingPtyServer(
            self.handle_line, unsolicited=self._alerts_due, waiting=self._alert_may_be_due,
            terminators=b"\r\n", max_line=256, faults=FaultInjector(faults, seed=seed),
            reply_tail=2, name="zaber",
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

    # -- alerts ------------------------------------------------------------------------
    def _alert_lines(self) -> list[str]:
        """The alerts of every device on the chain whose motions have ended (each once)."""
        return [alert for dev in self.devices.values() for alert in dev.alerts()]

    def _alerts_due(self) -> bytes | None:
        """What the watcher writes: the alerts due now, if any."""
        with self._lock:
            return _lines(self._alert_lines())

    def _alert_may_be_due(self) -> bool:
        """A motion ends in an alert and the clock runs by itself (real time, scaled)."""
        return 0.0 < self.clock.time_scale < math.inf and \
            any(axis.alert_pending for axis in self.axes.values())

    # -- protocol ----------------------------------------------------------------------
    def handle_line(self, line: bytes) -> bytes | None:
        """Answer one command line: the reply of every device it addresses (CR LF each),
        after the alerts of motions that ended before it and before those of motions that
        ended while it ran; None for a line that is no command or not for this chain."""
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
        with self._lock:
            targets = list(self.devices.values()) if address == 0 else \
                [self.devices[address]] if address in self.devices else []
            out = self._alert_lines()
            out += [self._reply(dev, axis, message_id, words) for dev in targets]
            out += self._alert_lines()
        self._server.notify()
        return _lines(out)

    def _reply(self, dev: EmulatedDevice, axis: int, message_id: int | None,
               words: list[str]) -> str:
        """One device's reply to a command (message_id None: the command gave none)."""
        status_axis = axis if 0 < axis <= len(dev.axes) else 0
        early = dev.status(status_axis) if (words or [""])[0] in _STATUS_FIRST else None
        bad_id = message_id is not None and message_id > 99
        try:
            if bad_id:
                raise Reject("BADMESSAGEID")
            flag, data = "OK", self._execute(dev, axis, words)
        except Reject as rejected:
            flag, data = "RJ", rejected.reason
        status, warning = early or dev.status(status_axis)
        head = f"{axis}" if message_id is None or bad_id else f"{axis} {message_id:02d}"
        return dev.message("@", f"{head} {flag} {status} {warning} {data}")

    def _execute(self, dev: EmulatedDevice, axis: int, words: list[str]) -> str:
        """Run one command on a device (axis 0: the whole device); returns the reply data."""
        if axis > len(dev.axes):
            raise Reject("BADAXIS")
        chosen = [dev.axes[axis]] if axis else list(dev.axes.values())
        self.received[" ".join(takewhile(lambda w: not is_integer(w), words[:2]))] += 1
        handler = _COMMANDS.get(words[0] if words else "")
        if handler is None:
            raise Reject("BADCOMMAND")
        return handler(self, dev, axis, chosen, words[1:])

    def _status(self, dev, axis, chosen, args: list[str]) -> str:
        """An empty command: only the reply's status and flag matter."""
        return "0"

    def _move(self, dev, axis, chosen, args: list[str]) -> str:
        """move abs N | move rel N | move min | move max (every axis when axis is 0)."""
        kind, values = (args[0], args[1:]) if args else ("", [])
        if kind in ("abs", "rel") and len(values) == 1:
            n = integer(values[0])
            targets = [n if kind == "abs" else a.data(a.motion.position()) + n for a in chosen]
        elif kind in ("min", "max") and not values:
            targets = [a.limit_min if kind == "min" else a.limit_max for a in chosen]
        else:
            raise Reject("BADCOMMAND" if kind not in ("abs", "rel", "min", "max")
                         else "BADDATA")
        for a, target in zip(chosen, targets, strict=True):
            a.check_move(target)
        for a, target in zip(chosen, targets, strict=True):
            a.move_to(target, dev.alerting)
        return "0"

    def _home(self, dev, axis, chosen, args: list[str]) -> str:
        """home: find the home position (0, or the nearest limit) and take it as reference."""
        if args:
            raise Reject("BADDATA")
        for a in chosen:
            a.home(dev.alerting)
        return "0"

    def _halt(self, dev, axis, chosen, args: list[str], how: str) -> str:
        """stop (how="stop"): decelerate to rest, a home it cuts short leaving no reference;
        estop (how="abort"): stop at once, without deceleration."""
        if args:
            raise Reject("BADDATA")
        for a in chosen:
            a.start(getattr(a.motion, how), dev.alerting and a.busy())
        return "0"

    def _warnings(self, dev, axis, chosen, args: list[str]) -> str:
        """warnings [clear]: the count and list of active flags; clear acknowledges latched
        faults and NI (WR stays until the axis is homed or its position set)."""
        if args not in ([], ["clear"]):
            raise Reject("BADDATA")
        flags = by_priority(list(dict.fromkeys(f for a in chosen for f in a.flags())))
        if args:
            for a in chosen:
                a.fault, a.interrupted = None, False
        return " ".join([f"{len(flags):02d}", *flags])

    def _get(self, dev, axis, chosen, args: list[str]) -> str:
        """get SETTING: a device setting (axis 0 only), or an axis setting, one value for
        each axis the command addresses."""
        if len(args) != 1:
            raise Reject("BADDATA" if args else "BADCOMMAND")
        if args[0] in dev.settings:
            if axis:
                raise Reject("DEVICEONLY")
            return dev.get(args[0])
        return " ".join(a.get(args[0]) for a in chosen)

    def _set(self, dev, axis, chosen, args: list[str]) -> str:
        """set SETTING VALUE: comm.alert / comm.checksum (0 or 1), or an axis setting."""
        if len(args) != 2:
            raise Reject("BADDATA" if args else "BADCOMMAND")
        name, value = args[0], integer(args[1])
        if name in dev.settings:
            if axis:
                raise Reject("DEVICEONLY")
            dev.set(name, value)
            return "0"
        for a in chosen:
            a.get(name)  # an unknown setting is rejected before any axis changes
        for a in chosen:
            a.set(name, value)
        return "0"

    def _system(self, dev, axis, chosen, args: list[str]) -> str:
        """system reset: the device restarts as from power-up (its axes stop at once and lose
        their reference); the reply shows the state before the reset."""
        if args != ["reset"]:
            raise Reject("BADCOMMAND")
        if axis:
            raise Reject("DEVICEONLY")
        for a in dev.axes.values():
            a.reset()
        return "0"


def _lines(messages: list[str]) -> bytes | None:
    """Messages as the bytes on the wire (CR LF after each); None for none."""
    return "".join(f"{msg}\r\n" for msg in messages).encode("ascii") if messages else None


#: commands whose reply shows the status from before they ran: the queries (the clock runs on
#: while they read, and an IDLE read first guarantees the position read next is the final
#: one) and `system reset` (the device answers, then restarts)
_STATUS_FIRST = {"", "get", "system"}

_COMMANDS = {
    "": ZaberEmulator._status, "move": ZaberEmulator._move, "home": ZaberEmulator._home,
    "stop": partial(ZaberEmulator._halt, how="stop"),
    "estop": partial(ZaberEmulator._halt, how="abort"),
    "warnings": ZaberEmulator._warnings, "get": ZaberEmulator._get, "set": ZaberEmulator._set,
    "system": ZaberEmulator._system,
}
