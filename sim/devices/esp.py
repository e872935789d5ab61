"""Emulated Newport ESP300/ESP301 motion controller speaking its ASCII command set on a pty.

Written from the ESP301 user's manual (EDH0235En1030, section 3 "Remote mode" and the
command reference in section 3.7, error list in Appendix A): commands are
`[axis]XX[?][parameter]`, terminated by a carriage return; several commands on one line
are separated by ';'. Commands do not answer; queries answer with one line ended by CR LF
(several queries on one line: their answers joined by ',' on one line - our reading).
Errors are not answered either: they go into a 10-deep FIFO read with TE? (code) and TB?
("code, timestamp, MESSAGE", the timestamp in 400 us servo ticks since reset: ESP300
manual, TB command, p. 3-138); axis errors are numbered axis*100 + code.

This module parses lines and dispatches; the handlers and the error buffer are in
`esp_commands`, an axis and its stored settings in `esp_axis`, the manual's command summary
in `esp_manual`. A command of that summary the emulator does not model is error 27 COMMAND
NOT ALLOWED, never 6.
"""

from __future__ import annotations

import re
import threading
from collections import Counter, deque
from collections.abc import Mapping

from sim.devices.esp_axis import EmulatedAxis, EspConfigError, Fail
from sim.devices.esp_commands import AXIS_ERRORS, GENERAL_ERRORS, HORIZON_S, EspCommands
from sim.devices.esp_manual import COMMAND_SUMMARY
from sim.devices.faults import FaultInjector, FaultSpec, InterlockInput
from sim.devices.motion import VirtualClock
from sim.devices.pty_server import PtyDevice, PtyServer

__all__ = ["AXIS_ERRORS", "GENERAL_ERRORS", "HORIZON_S", "EspConfigError", "EspEmulator"]

_UNIT = re.compile(r"(\d*)([A-Z]{2})(\?)?(.*)")
QUERY_ONLY = {"TP", "MD", "TE", "TB", "VE", "DP", "DV", "TV"}
GLOBAL = {"TE", "TB", "VE", "AB", "WT", "SM"}  # no axis number
ALL_AXES_OPTIONAL = {"ST", "WS", "UF", "QD"}  # no axis number = every axis


class EspEmulator(EspCommands, PtyDevice):
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
        self.axes = {n: EmulatedAxis(n, self.clock, t) for n, t in sorted(tables.items())}
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
                except Fail as fail:
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

    def _execute(self, unit: str) -> str | None:
        if unit.upper() == "*IDN?":
            return f"Newport Corporation,{self.model},0,3.0.2"
        match = _UNIT.fullmatch(unit.upper())
        if match is None:
            raise Fail(6)
        digits, cmd, question, param = match.groups()
        handler = self.handler(cmd)
        if handler is None:  # a manual command the emulator does not model is not error 6
            raise Fail(27 if cmd in COMMAND_SUMMARY else 6)
        self.received[cmd + (question or "")] += 1
        query = question is not None or cmd in QUERY_ONLY
        if cmd in QUERY_ONLY and param:
            raise Fail(7)
        if cmd in GLOBAL:
            return handler(None, query, param)
        if not digits:
            if cmd in ALL_AXES_OPTIONAL:
                return handler(None, query, param)
            raise Fail(37)
        axis = self.axes.get(int(digits))
        if axis is None:
            raise Fail(9)
        return handler(axis, query, param)
