"""Emulated Newport (Oriel) Cornerstone 130 / 260 monochromator speaking its serial statements
on a pty.

Written from the Cornerstone 260 manual (MCS260, appendix I "Low level commands and queries")
and the 130B / 260B manuals (15.3 command and query syntax, 15.4 standard mode, 15.9 error
codes). A statement ends with a line feed (a carriage return before it is allowed); statements
may be upper or lower case, a parameter follows after a space, responses are upper case and end
with CR LF. In standard mode over RS-232 every statement is echoed as it was received (`GOWAVE
500[lf]` echoes `GOWAVE 500[lf]`), and a query's answer follows its echo (`WAVE?[lf]` gives
`WAVE?[lf]500[cr][lf]`); a command has no answer. A statement it cannot take sets the status
byte to 32 and the error code: 1 not understood, 2 bad parameter, 3 wavelength destination not
allowed, 6 accessory not present (the filter-wheel accessory); `ERROR?` answers the code and
resets it to 0, `STB?` answers the status byte and clears it.

Statements are handled in order: while the drive moves (GOWAVE, STEP, a grating change) the
ones that follow wait in the input buffer (the 130B manual: "incoming commands are queued in
the input buffer while the CS130B is waiting"), so a query after a move is answered when the
move is over. Move times are this emulator's (the manuals give none): the wavelength drive
turns at WAVE_SPEED_NM_S (of a 1200 lines/mm grating: a coarser grating covers more
wavelength for the same turn), a grating change takes GRATING_CHANGE_S. A grating's reach is
the drive's turn limit: wavelength x lines/mm <= DRIVE_LIMIT. STEP counts the drive's motor
steps, STEP_NM of a 1200 lines/mm grating each (the manuals give no step size). Statements the
emulator does not model (slits, outports, handshake mode, the grating calibration table) are
not understood (error 1); ABORT, handled in turn like every statement, finds the drive at
rest.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock
from sim.devices.pty_server import PtyDevice, PtyServer

WAVE_SPEED_NM_S = 100.0  # the drive's speed at 1200 lines/mm
GRATING_CHANGE_S = 5.0
DRIVE_LIMIT = 1.68e6  # nm x lines/mm: 1400 nm on a 1200 lines/mm grating
STEP_NM = 0.01  # one motor step at 1200 lines/mm
REFERENCE_LINES = 1200.0
ERROR_STATUS = 32  # the status byte after an error
NOT_UNDERSTOOD, BAD_PARAMETER, NOT_ALLOWED, NO_ACCESSORY = 1, 2, 3, 6
#: the units UNITS takes and one nm in each (WN: wavenumbers, 1/cm: 1e7 / nm)
UNITS = ("NM", "UM", "WN")


class CornerstoneConfigError(ValueError):
    """An emulator set-up the monochromator cannot have (no grating, a bad grating table)."""


def _to_nm(value: float, units: str) -> float:
    """A wavelength in `units` as nm (a wavenumber of 0 has none: inf)."""
    if units == "UM":
        return value * 1000.0
    if units == "WN":
        return 1e7 / value if value else math.inf
    return value


def _from_nm(nm: float, units: str) -> float:
    if units == "UM":
        return nm / 1000.0
    if units == "WN":
        return 1e7 / nm if nm else math.inf
    return nm


def _number(value: float) -> str:
    """A number as the monochromator answers it: at most three decimals, no trailing zeros
    (the manual's `500`)."""
    return f"{value:.3f}".rstrip("0").rstrip(".")


class CornerstoneEmulator(PtyDevice):
    """A Cornerstone 130 (two gratings) or 260 (three) on a virtual clock, served on a pty.

    gratings: (lines per mm, label) of each grating, numbered from 1; grating and
    wavelength_nm: where it powers up; model and firmware: what INFO? answers; faults:
    injected on replies; seed: mixed into the fault seed.
    """

    protocol = "cornerstone"

    def __init__(self, clock: VirtualClock | None = None,
                 gratings: Sequence[tuple[float, str]] = ((1200.0, "1200 L/MM BLZ=500NM"),
                                                          (600.0, "600 L/MM BLZ=1000NM")),
                 faults: FaultSpec | None = None, seed: int = 0, grating: int = 1,
                 wavelength_nm: float = 500.0, model: str = "CS130B",
                 firmware: str = "V2.00"):
        if not 1 <= len(gratings) <= 3:
            raise CornerstoneConfigError(f"cornerstone: 1 to 3 gratings, got {len(gratings)}")
        if not all(lines > 0 for lines, _ in gratings):
            raise CornerstoneConfigError("cornerstone: a grating's lines per mm must be > 0")
        if not 1 <= grating <= len(gratings):
            raise CornerstoneConfigError(f"cornerstone: grating must be 1..{len(gratings)}, "
                                         f"got {grating!r}")
        self.clock = clock or VirtualClock(1.0)
        self.gratings = tuple((float(lines), label) for lines, label in gratings)
        self.grating, self.wavelength_nm = grating, float(wavelength_nm)
        if not self._reachable(self.wavelength_nm, grating):
            raise CornerstoneConfigError(f"cornerstone: {wavelength_nm} nm is beyond grating "
                                         f"{grating}")
        self.info = f"{model} {firmware}"
        self.units, self.shutter_open = "NM", False
        self.error_code, self.status_byte = 0, 0
        self.moves = 0
        self._busy_until = 0.0  # virtual time the drive's present motion ends
        self._lock = threading.Lock()
        self._server = PtyServer(self.handle_line, terminators=b"\n", max_line=128,
                                 faults=FaultInjector(faults, seed=seed), reply_tail=2,
                                 name="cornerstone")

    def handle_line(self, line: bytes) -> bytes:
        """Take one statement (its terminator stripped): its echo as received, then a query's
        answer; a motion under way is waited for first."""
        echo = line + b"\n"
        with self._lock:
            self._wait_for_drive()
            text = line.decode("ascii", errors="replace").rstrip("\r").strip()
            answer = self._execute(text.upper())
        return echo if answer is None else echo + answer.encode("ascii") + b"\r\n"

    def _wait_for_drive(self) -> None:
        left = self._busy_until - self.clock.now()
        if left > 0:
            self.clock.spend(left)

    def _fail(self, code: int) -> None:
        self.error_code, self.status_byte = code, ERROR_STATUS

    def _execute(self, text: str) -> str | None:
        word, _, argument = text.partition(" ")
        argument = argument.strip()
        handler = self._QUERIES.get(word) if not argument else None
        if handler is not None:
            return handler(self)
        command = self._COMMANDS.get(word)
        if command is None:
            self._fail(NO_ACCESSORY if word in ("FILTER", "FILTER?") else NOT_UNDERSTOOD)
            return None
        code = command(self, argument)
        if code:
            self._fail(code)
        return None

    # -- queries ----------------------------------------------------------------
    def _wave(self) -> str:
        return _number(_from_nm(self.wavelength_nm, self.units))

    def _grat(self) -> str:
        lines, label = self.gratings[self.grating - 1]
        return f"{self.grating},{_number(lines)},{label}"

    def _error(self) -> str:
        code, self.error_code = self.error_code, 0
        return str(code)

    def _stb(self) -> str:
        status, self.status_byte = self.status_byte, 0
        return str(status)

    def _step(self) -> str:
        return str(round(self.wavelength_nm * self._lines() / REFERENCE_LINES / STEP_NM))

    _QUERIES = {
        "WAVE?": _wave, "GRAT?": _grat, "ERROR?": _error, "STB?": _stb, "STEP?": _step,
        "INFO?": lambda self: self.info, "UNITS?": lambda self: self.units,
        "SHUTTER?": lambda self: "O" if self.shutter_open else "C",
    }

    # -- commands ---------------------------------------------------------------
    def _lines(self, grating: int | None = None) -> float:
        return self.gratings[(grating or self.grating) - 1][0]

    def _reachable(self, nm: float, grating: int) -> bool:
        return 0.0 <= nm and nm * self._lines(grating) <= DRIVE_LIMIT

    def _drive_to(self, nm: float, extra_s: float = 0.0) -> None:
        """Start the drive toward nm (the motion ends on the virtual clock)."""
        turn = abs(nm - self.wavelength_nm) * self._lines() / REFERENCE_LINES
        duration = turn / WAVE_SPEED_NM_S + extra_s
        if duration > 0:
            self._busy_until = self.clock.now() + duration
            self.moves += 1
        self.wavelength_nm = nm

    def _gowave(self, argument: str) -> int:
        try:
            nm = _to_nm(float(argument), self.units)
        except ValueError:
            return BAD_PARAMETER
        if not math.isfinite(nm):
            return BAD_PARAMETER
        if not self._reachable(nm, self.grating):
            return NOT_ALLOWED
        self._drive_to(nm)
        return 0

    def _step_by(self, argument: str) -> int:
        try:
            steps = int(argument)
        except ValueError:
            return BAD_PARAMETER
        nm = self.wavelength_nm + steps * STEP_NM * REFERENCE_LINES / self._lines()
        if not self._reachable(nm, self.grating):
            return NOT_ALLOWED
        self._drive_to(nm)
        return 0

    def _grating(self, argument: str) -> int:
        if argument not in {str(n) for n in range(1, len(self.gratings) + 1)}:
            return BAD_PARAMETER
        number = int(argument)
        if not self._reachable(self.wavelength_nm, number):
            return NOT_ALLOWED
        if number != self.grating:
            self.grating = number
            self._busy_until = self.clock.now() + GRATING_CHANGE_S
            self.moves += 1
        return 0

    def _shutter(self, argument: str) -> int:
        if argument not in ("O", "C"):
            return BAD_PARAMETER
        self.shutter_open = argument == "O"
        return 0

    def _units(self, argument: str) -> int:
        if argument not in UNITS:
            return BAD_PARAMETER
        self.units = argument
        return 0

    def _abort(self, argument: str) -> int:
        return BAD_PARAMETER if argument else 0

    _COMMANDS = {"GOWAVE": _gowave, "STEP": _step_by, "GRAT": _grating, "SHUTTER": _shutter,
                 "UNITS": _units, "ABORT": _abort}

