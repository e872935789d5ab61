"""Emulated Thorlabs FW102C / FW212C motorised filter wheel speaking its serial protocol on a pty.

Written from the FW102C manual (Rev H, chapter 5 "Software Control", 5.2.3 Keywords): 115200
baud 8N1, no flow control; every command and query is lower case, `keyword=argument` or
`keyword?`, ended by a carriage return. The wheel echoes each line it takes, answers a query on
a line of its own, and then shows its prompt: `pos?` CR gives `pos?` CR `3` CR `> `, `pos=3`
CR gives `pos=3` CR `> `. A keyword it does not know (an empty line too) answers `Command error
CMD_NOT_DEFINED`, a known keyword with a wrong or out-of-range argument `Command error
CMD_ARG_INVALID`, each on its own line before the prompt. A move answers when the wheel is in
place (the prompt comes after it), so a client's next line waits for the wheel.

Move times (not in the manual's tables): a half turn takes 3 s at high speed (`speed=1`), the
figure lab code driving the FW102C works with; slow speed (`speed=0`) is taken as half that
speed. The wheel turns the shorter way round, so between positions 1 and 6 of a 6-position
wheel it moves one position. Times pass on the emulator's VirtualClock.
"""

from __future__ import annotations

import re
import threading

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock
from sim.devices.pty_server import PtyDevice, PtyServer

IDN = "THORLABS FW102C/FW212C Filter Wheel version 1.07"
PROMPT = "> "
NOT_DEFINED = "Command error CMD_NOT_DEFINED"
ARG_INVALID = "Command error CMD_ARG_INVALID"
HALF_TURN_S = {1: 3.0, 0: 6.0}  # by speed mode: 1 high, 0 slow
WHEEL_TYPES = (6, 12)  # pcount: the FW102C's 6-position and the FW212C's 12-position wheel
_LINE = re.compile(r"([a-z*]+)(?:(\?)|=(.*))")
# settings with two values and what each is: trigger input/output, slow/high speed, sensors
# off when idle/on, 9600/115200 baud
_FLAGS = ("trig", "speed", "sensors", "baud")


class Fw102cConfigError(ValueError):
    """An emulator set-up the wheel cannot have (a wheel type or position out of range)."""


class Fw102cEmulator(PtyDevice):
    """An FW102C (6 positions) or FW212C (12) on a virtual clock, served on a pty.

    positions: the wheel type (pcount); position: where it powers up; speed: 1 high, 0 slow;
    faults: injected on replies (the prompt is kept whole); seed: mixed into the fault seed.
    `saved` holds the settings `save` stored for power-up.
    """

    protocol = "fw102c"

    def __init__(self, clock: VirtualClock | None = None, positions: int = 6,
                 faults: FaultSpec | None = None, seed: int = 0, position: int = 1,
                 speed: int = 1):
        if positions not in WHEEL_TYPES:
            raise Fw102cConfigError(f"fw102c: positions must be 6 or 12, got {positions!r}")
        if not (isinstance(position, int) and 1 <= position <= positions):
            raise Fw102cConfigError(f"fw102c: position must be 1..{positions}, got {position!r}")
        if speed not in (0, 1):
            raise Fw102cConfigError(f"fw102c: speed must be 0 or 1, got {speed!r}")
        self.clock = clock or VirtualClock(1.0)
        self.settings = {"pcount": positions, "trig": 0, "speed": speed, "sensors": 0,
                         "baud": 1}
        self.position = position
        self.saved = dict(self.settings)
        self.moves = 0  # moves made (a position command to where the wheel is makes none)
        self._lock = threading.Lock()
        self._server = PtyServer(self.handle_line, terminators=b"\r", ignore=b"\n",
                                 max_line=64, faults=FaultInjector(faults, seed=seed),
                                 reply_tail=len(PROMPT) + 1, name="fw102c")

    def handle_line(self, line: bytes) -> bytes:
        """Take one line: its echo, the answer or error (if any) and the prompt."""
        text = line.decode("ascii", errors="replace")
        with self._lock:
            answer = self._execute(text)
        lines = [text] if answer is None else [text, answer]
        return ("\r".join(lines) + "\r" + PROMPT).encode("ascii", errors="replace")

    def _execute(self, text: str) -> str | None:
        if text == "save":
            self.saved = dict(self.settings)
            return None
        match = _LINE.fullmatch(text)
        if match is None:
            return NOT_DEFINED
        keyword, query, argument = match.groups()
        if keyword == "*idn":
            return IDN if query else NOT_DEFINED
        if keyword == "pos":
            return str(self.position) if query else self._move(argument)
        if keyword == "pcount":
            return str(self.settings["pcount"]) if query else self._wheel_type(argument)
        if keyword in _FLAGS:
            return str(self.settings[keyword]) if query else self._flag(keyword, argument)
        return NOT_DEFINED

    def _move(self, argument: str) -> str | None:
        count = self.settings["pcount"]
        if not argument.isdigit() or not 1 <= int(argument) <= count:
            return ARG_INVALID
        target = int(argument)
        steps = abs(target - self.position)
        steps = min(steps, count - steps)
        if steps:
            self.clock.spend(steps / count * 2 * HALF_TURN_S[self.settings["speed"]])
            self.moves += 1
        self.position = target
        return None

    def _wheel_type(self, argument: str) -> str | None:
        if argument not in ("6", "12"):
            return ARG_INVALID
        self.settings["pcount"] = int(argument)
        self.position = min(self.position, self.settings["pcount"])
        return None

    def _flag(self, keyword: str, argument: str) -> str | None:
        if argument not in ("0", "1"):
            return ARG_INVALID
        self.settings[keyword] = int(argument)
        return None
