"""Emulated Thorlabs PM100-series power meter speaking its SCPI subset on a pty.

Written from the PM100D/PM100USB operation manuals ("Computer interface" / "SCPI
commands" chapter): program messages end in LF (CR LF accepted), keywords have a short
(upper-case part) and a long form in any letter case, optional nodes in brackets,
several message units separated by ';' (a unit without a leading ':' first continues the
previous header's path, as SCPI says; failing that it is read from the root). Replies:
one line ended by LF, several query answers joined by ';'. Errors go into the SCPI error
queue read by SYST:ERR? as `code,"message"` (standard SCPI codes); a failed query answers
nothing. SYST:SENS:IDN? gives name, serial number, calibration message, type, subtype,
flags. The optical power comes from a PowerSource through sim.devices.photodiode.
"""

from __future__ import annotations

import math
import re
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.photodiode import PhotodiodeModel, PowerSource
from sim.devices.pty_server import PtyDevice, PtyServer

SCPI_ERRORS = {
    0: "No error",
    -101: "Invalid character",
    -102: "Syntax error",
    -104: "Data type error",
    -108: "Parameter not allowed",
    -109: "Missing parameter",
    -113: "Undefined header",
    -114: "Header suffix out of range",
    -131: "Invalid suffix",
    -138: "Suffix not allowed",
    -222: "Data out of range",
    -230: "Data corrupt or stale",
    -350: "Queue overflow",
    -224: "Illegal parameter value",
    -363: "Input buffer overrun",
}
ERROR_QUEUE_DEPTH = 10


@dataclass(frozen=True)
class SensorInfo:
    """What SYST:SENS:IDN? reports (flags: 1 power sensor, 16 response settable,
    32 wavelength settable, 256 temperature sensor)."""

    name: str = "S121C"
    serial: str = "EMU00001"
    calibration: str = "01-Jan-2026"
    type: int = 1  # photodiode sensor
    subtype: int = 1
    flags: int = 1 + 16 + 32
    wavelength_min_nm: float = 400.0
    wavelength_max_nm: float = 1100.0


class _ScpiError(Exception):
    def __init__(self, code: int):
        self.code = code


@dataclass(frozen=True)
class _Node:
    short: str
    long: str
    optional: bool
    numbered: bool  # takes a numeric keyword suffix (SENSe1); 1 is the only channel


def _pattern(spec: str) -> tuple[_Node, ...]:
    """'[SENSe#]:POWer[:DC]:RANGe' -> nodes with short/long forms, optional and numbered
    ('#') flags."""
    nodes = []
    for opt, word, numbered in re.findall(r"(\[?):?([A-Za-z*]+)(#?)\]?", spec):
        short = "".join(ch for ch in word if ch.isupper() or ch == "*")
        nodes.append(_Node(short, word.upper(), bool(opt), bool(numbered)))
    return tuple(nodes)


Token = tuple[str, str]  # (keyword, numeric suffix or "")


def _matches(nodes: tuple[_Node, ...], tokens: list[Token]) -> bool:
    if not nodes:
        return not tokens
    head, rest = nodes[0], nodes[1:]
    if (tokens and tokens[0][0] in (head.short, head.long)
            and (head.numbered or not tokens[0][1]) and _matches(rest, tokens[1:])):
        return True
    return head.optional and _matches(rest, tokens)


_UNIT = re.compile(r"(:?)([A-Za-z*][A-Za-z0-9:*]*)(\?)?(?:\s+(.*))?")
_KEYWORD = re.compile(r"([A-Z*]+)(\d*)")
_NRF = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+)(?:E[+-]?\d+)?)\s*([A-Z]*)")
# Unit suffixes a numeric parameter may carry (upper case; SCPI reads M as milli, so MW is
# a milliwatt), as factors to the parameter's own unit: nm for the wavelength, W for
# ranges (bare SI multipliers too, as the manual's "M, K, or u" engineering suffixes).
WAVELENGTH_UNITS = {"NM": 1.0, "UM": 1e3}
POWER_UNITS = {f"{prefix}{unit}": factor
               for prefix, factor in (("", 1.0), ("K", 1e3), ("M", 1e-3), ("U", 1e-6),
                                      ("N", 1e-9), ("P", 1e-12))
               for unit in ("W", "") if prefix or unit}


def _nr3(value: float) -> str:
    return f"{value:.6E}"


SCPI_NAN = 9.91e37  # SCPI-99's not-a-number: what the meter answers when it has no reading


class Pm100Emulator(PtyDevice):
    """A PM100-series meter with a photodiode sensor, served on a pty.

    source: a PowerSource (or any callable returning watts) giving the true power at the
    detector now; detector: the [sim.detector] table for PhotodiodeModel; seed: noise and
    fault seed; place: the commanded stage positions now (deg), which key the noise (None:
    the noise keys on the range and the visit count only).
    """

    protocol = "pm100"

    def __init__(
        self,
        source: PowerSource | Callable[[], float],
        wavelength_nm: float = 632.8,
        faults: FaultSpec | None = None,
        seed: int = 0,
        detector: Mapping | None = None,
        light_wavelength_nm: float | None = None,
        sensor: SensorInfo | None = None,
        model: str = "PM100D",
        place: Callable[[], Sequence[float]] | None = None,
    ):
        self._place = place or tuple
        self._power = source.power_w if hasattr(source, "power_w") else source
        if not callable(self._power):
            raise TypeError("pm100: source must be a PowerSource or a callable returning W")
        self.sensor = sensor or SensorInfo()
        if not self.sensor.wavelength_min_nm <= wavelength_nm <= self.sensor.wavelength_max_nm:
            raise ValueError(
                f"pm100: wavelength_nm {wavelength_nm!r} outside the sensor's range "
                f"{self.sensor.wavelength_min_nm:g}..{self.sensor.wavelength_max_nm:g} nm"
            )
        self.photodiode = PhotodiodeModel(detector, seed=seed,
                                          light_wavelength_nm=light_wavelength_nm)
        self.idn = f"THORLABS,{model},P0000000,2.4.0"
        self.default_wavelength_nm = float(wavelength_nm)
        self.errors: deque[int] = deque()
        self._lock = threading.Lock()
        self._reset()
        self._commands = self._command_table()
        self._server = PtyServer(
            self.handle_line, terminators=b"\n", ignore=b"\r", max_line=512,
            on_overflow=self._overflow, faults=FaultInjector(faults, seed=seed),
            reply_tail=1, name="pm100",
        )

    def _reset(self) -> None:
        self.wavelength_nm = self.default_wavelength_nm
        self.averaging = 1
        self.autorange = True
        self.range_w = self.photodiode.ranges_w[-1]
        self.last_reading: float | None = None

    # -- error queue --------------------------------------------------------------
    def _push(self, code: int) -> None:
        """SCPI error queue: when full, the newest entry becomes -350 Queue overflow."""
        if len(self.errors) >= ERROR_QUEUE_DEPTH:
            self.errors[-1] = -350
        else:
            self.errors.append(code)

    def _overflow(self) -> None:
        with self._lock:
            self._push(-363)

    # -- message parsing --------------------------------------------------------
    def handle_line(self, line: bytes) -> bytes | None:
        """Execute one program message; returns the response message (LF) or None."""
        with self._lock:
            if any(b < 0x20 or b > 0x7E for b in line.replace(b"\t", b" ")):
                self._push(-101)
                return None
            replies: list[str] = []
            path: list[str] = []
            for unit in line.decode("ascii").split(";"):
                unit = unit.strip()
                if not unit:
                    continue
                try:
                    reply, path = self._execute(unit, path)
                except _ScpiError as exc:
                    self._push(exc.code)
                    continue
                if reply is not None:
                    replies.append(reply)
            return (";".join(replies) + "\n").encode("ascii") if replies else None

    def _execute(self, unit: str, path: list[str]) -> tuple[str | None, list[str]]:
        match = _UNIT.fullmatch(unit)
        if match is None:
            raise _ScpiError(-102)
        rooted, header, question, params = match.groups()
        words = header.upper().split(":")
        if any(not w for w in words):
            raise _ScpiError(-102)
        keywords = [_KEYWORD.fullmatch(w) for w in words]
        if any(k is None for k in keywords):
            raise _ScpiError(-113)
        tokens = [(k.group(1), k.group(2)) for k in keywords]
        common = tokens[0][0].startswith("*")
        query = question is not None
        candidates = [tokens] if rooted or common else [path + tokens, tokens]
        for full in candidates:
            for nodes, can_query, can_set, action in self._commands:
                if _matches(nodes, full) and (can_query if query else can_set):
                    if any(suffix and int(suffix) != 1 for _, suffix in tokens):
                        raise _ScpiError(-114)  # one sensor channel: only suffix 1 exists
                    args = [a.strip() for a in params.split(",")] if params else []
                    return action(query, args), path if common else full[:-1]
        raise _ScpiError(-113)

    @staticmethod
    def _no_args(args: list[str]) -> None:
        if args:
            raise _ScpiError(-108)

    @staticmethod
    def _one_arg(args: list[str]) -> str:
        if not args:
            raise _ScpiError(-109)
        if len(args) > 1:
            raise _ScpiError(-108)
        return args[0].upper()

    @staticmethod
    def _number(text: str, lo: float, hi: float, units: Mapping[str, float] | None = None
                ) -> float:
        """A decimal numeric parameter (or MIN / MAX), optionally with one of `units`
        (e.g. 633NM, 633 nm, 1.5 uW), in the parameter's own unit."""
        if text in ("MIN", "MINIMUM"):
            return lo
        if text in ("MAX", "MAXIMUM"):
            return hi
        match = _NRF.fullmatch(text)
        if match is None:
            raise _ScpiError(-104)
        number, suffix = match.groups()
        if suffix and units is None:
            raise _ScpiError(-138)
        if suffix and suffix not in units:
            raise _ScpiError(-131)
        value = float(number) * (units[suffix] if suffix else 1.0)
        if not (math.isfinite(value) and lo <= value <= hi):
            raise _ScpiError(-222)
        return value

    @staticmethod
    def _bool(text: str) -> bool:
        if text in ("ON", "1"):
            return True
        if text in ("OFF", "0"):
            return False
        raise _ScpiError(-104)

    def _limits_query(self, args: list[str], lo: float, hi: float, now: float) -> str:
        """A setting's '?': its value now, or with MIN / MAX its allowed bounds."""
        if not args:
            return _nr3(now)
        word = self._one_arg(args)
        if word in ("MIN", "MINIMUM"):
            return _nr3(lo)
        if word in ("MAX", "MAXIMUM"):
            return _nr3(hi)
        raise _ScpiError(-224)

    # -- command table ----------------------------------------------------------
    def _command_table(self):
        """(pattern nodes, query allowed, set allowed, action(query, args))."""
        table = [
            ("*IDN", True, False, self._idn),
            ("*RST", False, True, self._rst),
            ("*CLS", False, True, self._cls),
            ("*OPC", True, False, lambda q, a: "1"),
            ("SYSTem:ERRor[:NEXT]", True, False, self._syst_err),
            ("SYSTem:SENSor:IDN", True, False, self._sensor_idn),
            ("MEASure#[:SCALar]:POWer", True, False, self._meas_pow),
            ("CONFigure#[:SCALar]:POWer", False, True, self._conf_pow),
            ("CONFigure#", True, False, self._conf_query),
            ("INITiate#[:IMMediate]", False, True, self._init),
            ("FETCh#", True, False, self._fetch),
            ("READ#", True, False, self._read),
            ("[SENSe#]:CORRection:WAVelength", True, True, self._wavelength),
            ("[SENSe#]:POWer[:DC]:RANGe:AUTO", True, True, self._range_auto),
            ("[SENSe#]:POWer[:DC]:RANGe[:UPPer]", True, True, self._range),
            ("[SENSe#]:AVERage[:COUNt]", True, True, self._average),
            ("[SENSe#]:CORRection:COLLect:ZERO[:INITiate]", False, True, self._zero),
            ("[SENSe#]:CORRection:COLLect:ZERO:STATe", True, False, lambda q, a: "0"),
            ("[SENSe#]:CORRection:COLLect:ZERO:MAGNitude", True, False,
             lambda q, a: _nr3(self.photodiode.zero_offset_w)),
        ]
        return [(_pattern(spec), q, s, action) for spec, q, s, action in table]

    # -- actions ----------------------------------------------------------------
    def _idn(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        return self.idn

    def _rst(self, query: bool, args: list[str]) -> None:
        self._no_args(args)
        self._reset()

    def _cls(self, query: bool, args: list[str]) -> None:
        self._no_args(args)
        self.errors.clear()

    def _syst_err(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        code = self.errors.popleft() if self.errors else 0
        return f'{code},"{SCPI_ERRORS[code]}"'

    def _sensor_idn(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        s = self.sensor
        return f"{s.name},{s.serial},{s.calibration},{s.type},{s.subtype},{s.flags}"

    def _measure(self) -> float:
        """Take one averaged reading of the source's power now (autoranging if on); SCPI_NAN
        when the invalid-reading fault strikes."""
        if self._server.faults.invalid_reading():
            self.last_reading = SCPI_NAN
            return SCPI_NAN
        try:
            power = float(self._power())
            result = self.photodiode.measure(
                power, None if self.autorange else self.range_w, self.averaging,
                self.wavelength_nm, self._place(),
            )
        except (ValueError, TypeError, ArithmeticError):
            self.last_reading = None
            raise _ScpiError(-230) from None
        self.range_w = result.range_w
        self.last_reading = result.reading_w
        return result.reading_w

    def _conf_pow(self, query: bool, args: list[str]) -> None:
        self._no_args(args)
        self.last_reading = None

    def _conf_query(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        return "POW"

    def _meas_pow(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        return _nr3(self._measure())

    def _init(self, query: bool, args: list[str]) -> None:
        self._no_args(args)
        self._measure()

    def _fetch(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        if self.last_reading is None:
            raise _ScpiError(-230)
        return _nr3(self.last_reading)

    def _read(self, query: bool, args: list[str]) -> str:
        self._no_args(args)
        return _nr3(self._measure())

    def _wavelength(self, query: bool, args: list[str]) -> str | None:
        lo, hi = self.sensor.wavelength_min_nm, self.sensor.wavelength_max_nm
        if query:
            return self._limits_query(args, lo, hi, self.wavelength_nm)
        self.wavelength_nm = self._number(self._one_arg(args), lo, hi, WAVELENGTH_UNITS)
        return None

    def _range_auto(self, query: bool, args: list[str]) -> str | None:
        if query:
            self._no_args(args)
            return "1" if self.autorange else "0"
        self.autorange = self._bool(self._one_arg(args))
        return None

    def _range(self, query: bool, args: list[str]) -> str | None:
        ranges = self.photodiode.ranges_w
        if query:
            return self._limits_query(args, ranges[0], ranges[-1], self.range_w)
        value = self._number(self._one_arg(args), 0.0, ranges[-1], POWER_UNITS)
        self.range_w = self.photodiode.range_for(value)
        self.autorange = False
        return None

    def _average(self, query: bool, args: list[str]) -> str | None:
        if query:
            self._no_args(args)
            return str(self.averaging)
        value = self._number(self._one_arg(args), 1, 10000)
        if value != int(value):
            raise _ScpiError(-222)
        self.averaging = int(value)
        return None

    def _zero(self, query: bool, args: list[str]) -> None:
        self._no_args(args)
        self.photodiode.zero(self.wavelength_nm)
