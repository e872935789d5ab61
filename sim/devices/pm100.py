"""Emulated Thorlabs PM100-family power meter (PM100D, PM100A, PM100USB, PM400) speaking the
SCPI command set of its manuals on a pty.

Written from the PM100D / PM100USB / PM400 operation manuals ("SCPI commands" / "Computer
interface" chapters) and Thorlabs' own PM100 instrument drivers (PM100D_Drv.c, TLPM.h: the
commands they send, the status register bits): program messages end in LF (CR LF
accepted), keywords have a short (upper-case part) and a long form in any letter case,
optional nodes in brackets, several message units separated by ';'. A unit without a leading
':' continues the previous header's path, as SCPI and the manual say ("CORR:BEAM 1; WAVE
1310" sets both); failing that it is read from the root only if it names a root keyword
itself, so "MEAS:POW?;SYST:ERR?" works while "CORR:BEAM 1;AVER 300", which needs the implied
SENSe, is an undefined header, as the manual says; common commands leave the path as it is.
Replies: one line ended by LF, several query answers joined by ';'. Errors go into the SCPI
error queue read by SYST:ERR? as `code,"message"` and set their class's bit of the Standard
Event Status Register; a failed query answers nothing. The console (`model`) gives the *IDN?
answer and the front-panel commands (display, clock, beeper: pm100_panel), the sensor head
(`sensor`) SYST:SENS:IDN? and the wavelength range; the optical power comes from a
PowerSource through sim.devices.photodiode.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence

from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import PhotodiodeModel, PowerSource
from sim.devices.pm100_models import DEFAULT_HEAD, SensorHead, console, head
from sim.devices.pm100_panel import Panel
from sim.devices.pty_server import PtyDevice, PtyServer
from sim.devices.scpi_program import (
    Limits,
    ScpiError,
    attribute_flag,
    choice,
    flag_setting,
    integer,
    limits_query,
    matches,
    no_args,
    nr3,
    number,
    one_arg,
    optional_arg,
    parse_unit,
    pattern,
)
from sim.devices.scpi_status import StatusModel, StatusRegister, register_commands

ERROR_QUEUE_DEPTH = 10
# Unit suffixes a numeric parameter may carry (upper case; SCPI reads M as milli, so MW is
# a milliwatt), as factors to the parameter's own unit: nm for the wavelength, W for power,
# A for current, mm for the beam (bare SI multipliers too, as the manual's "M, K, or u").
WAVELENGTH_UNITS = {"NM": 1.0, "UM": 1e3}
_PREFIXES = (("", 1.0), ("K", 1e3), ("M", 1e-3), ("U", 1e-6), ("N", 1e-9), ("P", 1e-12))
POWER_UNITS = {f"{p}{u}": f for p, f in _PREFIXES for u in ("W", "") if p or u}
CURRENT_UNITS = {f"{p}{u}": f for p, f in _PREFIXES for u in ("A", "") if p or u}
LENGTH_UNITS = {"MM": 1.0, "UM": 1e-3, "CM": 10.0}
RESPONSE_UNITS = {"A": 1.0, "MA": 1e-3}  # the manual writes the A/W responsivity as [A]
SCPI_NAN = 9.91e37  # SCPI-99's not-a-number: what the meter answers when it has no reading
SCPI_NINF = -9.9e37  # SCPI-99's negative infinity: 0 W in dBm
POWER_UP_NM = 632.8  # the correction wavelength at power-up, within the head's range

# Status byte bits and register bits as Thorlabs' TLPM.h defines them for the PM100 family
STB_AUX, STB_MEAS, STB_EAV, STB_QUES, STB_OPER = 0x01, 0x02, 0x04, 0x08, 0x80
OPER_RANG = 0x0004  # changing its range (autorange)
OPER_MEAS = 0x0010  # actively measuring
OPER_CORR = 0x0080  # performing a correction (the dark zero)
OPER_SENS = 0x0100  # sensor connected and operable
OPER_DATA = 0x0200  # measurement data ready for fetch
QUES_POW = 0x0008  # questionable power measurement (over range, or no valid reading)

RESPONSE_LIMITS = (1e-5, 10.0)  # settable photodiode responsivity, A/W
ATTENUATION_LIMITS = Limits(-60.0, 60.0, 0.0)  # SENS:CORR:LOSS:INP:MAGN, dB
AVERAGING_LIMITS = Limits(1, 10000, 1)
SAMPLE_S = 3e-3  # the manual's SENS:AVER:COUN: "1 sample takes approx. 3ms"


class Pm100Emulator(PtyDevice):
    """A PM100-family meter with a C-series sensor head, served on a pty.

    source: a PowerSource (or any callable returning watts) giving the true power at the
    detector now; wavelength_nm: the correction wavelength at power-up and after *RST (None:
    632.8 nm, or the head's nearest bound); detector: the [sim.detector] table for
    PhotodiodeModel; seed: noise and fault seed; sensor: the head (a SensorHead or its name,
    pm100_models.HEADS); model: the console (PM100D, PM100A, PM100USB, PM400); place: the
    commanded stage positions now (deg), which key the noise (None: the noise keys on the
    range and the visit count only); wall: the clock SYST:DATE / TIME run on (epoch seconds);
    clock: the bench's VirtualClock a reading takes its time on (SAMPLE_S per averaged sample;
    None: no time).
    """

    protocol = "pm100"

    def __init__(
        self,
        source: PowerSource | Callable[[], float],
        wavelength_nm: float | None = None,
        faults: FaultSpec | None = None,
        seed: int = 0,
        detector: Mapping | None = None,
        light_wavelength_nm: float | None = None,
        sensor: SensorHead | str | None = None,
        model: str = "PM100D",
        place: Callable[[], Sequence[float]] | None = None,
        wall: Callable[[], float] = time.time,
        clock: VirtualClock | None = None,
    ):
        self._place = place or tuple
        self.clock = clock
        self._power = source.power_w if hasattr(source, "power_w") else source
        if not callable(self._power):
            raise TypeError("pm100: source must be a PowerSource or a callable returning W")
        self.sensor = head(sensor or DEFAULT_HEAD) if not isinstance(sensor, SensorHead) \
            else sensor
        self.console = console(model)
        self.default_wavelength_nm = self._power_up_wavelength(wavelength_nm)
        self.photodiode = PhotodiodeModel(detector, seed=seed,
                                          light_wavelength_nm=light_wavelength_nm)
        self.idn = self.console.idn
        self.operation, self.questionable = StatusRegister(), StatusRegister()
        self.measurement, self.auxiliary = StatusRegister(), StatusRegister()
        self.status = StatusModel({STB_OPER: self.operation, STB_QUES: self.questionable,
                                   STB_MEAS: self.measurement, STB_AUX: self.auxiliary},
                                  error_queue_bit=STB_EAV, error_queue_depth=ERROR_QUEUE_DEPTH)
        self.operation.condition = OPER_SENS  # a head is connected from power-up
        self.panel = Panel(self.console, wall)
        self._lock = threading.Lock()
        self._answers: list[str] = []  # this message's answers so far (MAV)
        self._reset()
        self._commands = self._command_table()
        self._server = PtyServer(
            self.handle_line, terminators=b"\n", ignore=b"\r", max_line=512,
            on_overflow=self._overflow, faults=FaultInjector(faults, seed=seed),
            reply_tail=1, name="pm100",
        )

    def _power_up_wavelength(self, wavelength_nm: float | None) -> float:
        lo, hi = self.sensor.wavelength_min_nm, self.sensor.wavelength_max_nm
        if wavelength_nm is None:
            return min(max(POWER_UP_NM, lo), hi)
        if not lo <= wavelength_nm <= hi:
            raise ValueError(f"pm100: wavelength_nm {wavelength_nm!r} outside the sensor "
                             f"head {self.sensor.name}'s range {self.sensor.range_text}")
        return float(wavelength_nm)

    def _reset(self) -> None:
        """*RST and power-up: every measurement setting to its default (the status registers
        and the panel's system settings are not reset, as IEEE 488.2 says)."""
        self.wavelength_nm = self.default_wavelength_nm
        self.averaging = 1
        self.autorange = True
        self.range_w = self.photodiode.ranges_w[-1]
        self.beam_mm = self.sensor.aperture_mm
        self.user_response: float | None = None
        self.attenuation_db = 0.0
        self.references = {"POW": [0.0, False], "CURR": [0.0, False]}
        self.power_unit = "W"
        self.mode = "POW"
        self.lowpass = False
        self.last_reading: float | None = None
        self.operation.assign(OPER_DATA, False)

    def _overflow(self) -> None:
        with self._lock:
            self.status.push_error(-363)

    # -- message parsing --------------------------------------------------------
    def handle_line(self, line: bytes) -> bytes | None:
        """Execute one program message; returns the response message (LF) or None."""
        with self._lock:
            if any(b < 0x20 or b > 0x7E for b in line.replace(b"\t", b" ")):
                self.status.push_error(-101)
                return None
            self._answers = []
            path: list[tuple[str, str]] = []
            for text in line.decode("ascii").split(";"):
                text = text.strip()
                if not text:
                    continue
                try:
                    reply, path = self._execute(text, path)
                except ScpiError as exc:
                    self.status.push_error(exc.code)
                    continue
                if reply is not None:
                    self._answers.append(reply)
            return (";".join(self._answers) + "\n").encode("ascii") if self._answers else None

    def _execute(self, text: str, path: list) -> tuple[str | None, list]:
        unit = parse_unit(text)
        candidates = [(unit.tokens, False)] if unit.rooted or unit.common or not path else [
            (path + unit.tokens, False), (unit.tokens, True)]
        for full, fallback in candidates:
            for nodes, can_query, can_set, action in self._commands:
                if (matches(nodes, full) and (can_query if unit.query else can_set)
                        and (not fallback or nodes[0].spells(full[0][0]))):
                    if any(suffix and int(suffix) != 1 for _, suffix in unit.tokens):
                        raise ScpiError(-114)  # one sensor channel: only suffix 1 exists
                    return action(unit.query, unit.args), path if unit.common else full[:-1]
        raise ScpiError(-113)

    # -- command table ----------------------------------------------------------
    def _command_table(self) -> list:
        """(pattern nodes, query allowed, set allowed, action(query, args))."""
        table = [
            ("*IDN", True, False, self._idn),
            ("*RST", False, True, self._rst),
            ("*TST", True, False, self._tst),
            *self.status.common_commands(lambda: bool(self._answers)),
            ("SYSTem:VERSion", True, False, lambda q, a: no_args(a) or "1999.0"),
            ("SYSTem:SENSor:IDN", True, False, self._sensor_idn),
            *register_commands({"OPERation": self.operation, "QUEStionable": self.questionable,
                                "MEASurement": self.measurement, "AUXiliary": self.auxiliary}),
            *self.panel.commands(),
            ("ABORt#", False, True, self._abort),
            ("INITiate#[:IMMediate]", False, True, self._init),
            ("FETCh#", True, False, self._fetch),
            ("READ#", True, False, self._read),
            ("CONFigure#", True, False, lambda q, a: no_args(a) or self.mode),
            ("CONFigure#[:SCALar]:POWer", False, True, self._configure("POW")),
            ("CONFigure#[:SCALar]:CURRent[:DC]", False, True, self._photodiode(
                self._configure("CURR"))),
            ("CONFigure#[:SCALar]:PDENsity", False, True, self._configure("PDEN")),
            ("MEASure#[:SCALar]:POWer", True, False, self._measure_as("POW")),
            ("MEASure#[:SCALar]:CURRent[:DC]", True, False, self._photodiode(
                self._measure_as("CURR"))),
            ("MEASure#[:SCALar]:PDENsity", True, False, self._measure_as("PDEN")),
            ("[SENSe#]:AVERage[:COUNt]", True, True, self._average),
            ("[SENSe#]:CORRection:WAVelength/WAVE", True, True, self._wavelength),
            ("[SENSe#]:CORRection:BEAMdiameter", True, True, self._beam),
            ("[SENSe#]:CORRection:LOSS[:INPut][:MAGNitude]", True, True, self._attenuation),
            ("[SENSe#]:CORRection:POWer[:PDIode][:RESPonse]", True, True,
             self._photodiode(self._response)),
            ("[SENSe#]:CORRection:COLLect:ZERO[:INITiate]", False, True, self._zero),
            ("[SENSe#]:CORRection:COLLect:ZERO:ABORt", False, True, lambda q, a: no_args(a)),
            ("[SENSe#]:CORRection:COLLect:ZERO:STATe", True, False,
             lambda q, a: no_args(a) or "0"),
            ("[SENSe#]:CORRection:COLLect:ZERO:MAGNitude", True, False,
             lambda q, a: no_args(a) or nr3(self.photodiode.zero_offset_w)),
            ("[SENSe#]:POWer[:DC]:RANGe:AUTO", True, True, attribute_flag(self, "autorange")),
            ("[SENSe#]:POWer[:DC]:RANGe[:UPPer]", True, True, self._range(1.0, POWER_UNITS)),
            ("[SENSe#]:POWer[:DC]:REFerence", True, True, self._reference("POW")),
            ("[SENSe#]:POWer[:DC]:REFerence:STATe", True, True, self._reference_state("POW")),
            ("[SENSe#]:POWer[:DC]:UNIT", True, True, self._unit),
            ("[SENSe#]:CURRent[:DC]:RANGe:AUTO", True, True,
             self._photodiode(attribute_flag(self, "autorange"))),
            ("[SENSe#]:CURRent[:DC]:RANGe[:UPPer]", True, True,
             self._photodiode(self._range(None, CURRENT_UNITS))),
            ("[SENSe#]:CURRent[:DC]:REFerence", True, True,
             self._photodiode(self._reference("CURR"))),
            ("[SENSe#]:CURRent[:DC]:REFerence:STATe", True, True,
             self._photodiode(self._reference_state("CURR"))),
            ("INPut#:PDIode:FILTer:LPASs:STATe", True, True,
             self._photodiode(attribute_flag(self, "lowpass"))),
        ]
        return [(pattern(spec), q, s, action) for spec, q, s, action in table]

    def _photodiode(self, action: Callable) -> Callable:
        """A command of photodiode heads only: -241 Hardware missing with a thermal head."""
        def guarded(query: bool, args: list[str]):
            if self.sensor.kind != "photodiode":
                raise ScpiError(-241)
            return action(query, args)
        return guarded

    # -- IEEE 488.2 common commands and status --------------------------------------
    def _idn(self, query: bool, args: list[str]) -> str:
        no_args(args)
        return self.idn

    def _rst(self, query: bool, args: list[str]) -> None:
        no_args(args)
        self._reset()

    def _tst(self, query: bool, args: list[str]) -> str:
        no_args(args)
        return "0"  # self-test passed

    def _sensor_idn(self, query: bool, args: list[str]) -> str:
        no_args(args)
        s = self.sensor
        return f"{s.name},{s.serial},{s.calibration},{s.type},{s.subtype},{s.flags}"

    # -- measuring ------------------------------------------------------------------
    def _measure(self) -> float:
        """Take one averaged reading of the source's power now (autoranging if on), in the
        configured quantity and unit; SCPI_NAN when the invalid-reading fault strikes. The
        light is the source's as the reading begins; the reading then takes its time."""
        self.operation.pulse(OPER_MEAS)
        try:
            return self._sampled()
        finally:
            if self.clock is not None:
                self.clock.spend(self.averaging * SAMPLE_S)

    def _sampled(self) -> float:
        """The averaged samples of _measure, as the reply gives them."""
        if self._server.faults.invalid_reading():
            self._stored(SCPI_NAN, questionable=True)
            return SCPI_NAN
        try:
            power = float(self._power())
            result = self.photodiode.measure(
                power, None if self.autorange else self.range_w, self.averaging,
                self.wavelength_nm, self._place(),
            )
        except (ValueError, TypeError, ArithmeticError):
            self._stored(None, questionable=True)
            raise ScpiError(-230) from None
        if result.range_w != self.range_w:
            self.operation.pulse(OPER_RANG)
        self.range_w = result.range_w
        over = result.saturated or result.reading_w > result.range_w
        return self._stored(self._quantity(result.reading_w), questionable=over)

    def _stored(self, value: float | None, questionable: bool) -> float | None:
        """Keep a reading for FETCh? (None: none), with its data-ready and questionable bits."""
        self.last_reading = value
        self.operation.assign(OPER_DATA, value is not None)
        self.questionable.assign(QUES_POW, questionable)
        return value

    def _responsivity(self) -> float:
        """The photodiode responsivity in use, A/W: the head's at the wavelength, or the one
        set by SENS:CORR:POW:PDI:RESP."""
        return self.user_response or self.photodiode.responsivity_a_w(self.wavelength_nm)

    def _quantity(self, reading_w: float) -> float:
        """A reading (W, as the head's responsivity gives it) in the configured quantity:
        power (W or dBm) corrected by the set responsivity and attenuation, photocurrent (A)
        or power density (W/cm^2 over the beam diameter), less the delta reference if on."""
        current = reading_w * self.photodiode.responsivity_a_w(self.wavelength_nm)
        if self.mode == "CURR":
            return current - self._reference_value("CURR")
        power = current / self._responsivity() * 10.0 ** (self.attenuation_db / 10.0)
        if self.mode == "PDEN":
            return power / (math.pi * (self.beam_mm / 20.0) ** 2)
        if self.power_unit == "DBM":
            dbm = _dbm(power)
            reference = self._reference_value("POW")
            return dbm - _dbm(reference) if reference and dbm > SCPI_NINF else dbm
        return power - self._reference_value("POW")

    def _reference_value(self, quantity: str) -> float:
        value, on = self.references[quantity]
        return value if on else 0.0

    def _abort(self, query: bool, args: list[str]) -> None:
        no_args(args)
        self._stored(None, questionable=False)

    def _init(self, query: bool, args: list[str]) -> None:
        no_args(args)
        self._measure()

    def _fetch(self, query: bool, args: list[str]) -> str:
        no_args(args)
        if self.last_reading is None:
            raise ScpiError(-230)
        return nr3(self.last_reading)

    def _read(self, query: bool, args: list[str]) -> str:
        no_args(args)
        return nr3(self._measure())

    def _configure(self, mode: str) -> Callable:
        def configure(query: bool, args: list[str]) -> None:
            no_args(args)
            self.mode = mode
            self._stored(None, questionable=False)
        return configure

    def _measure_as(self, mode: str) -> Callable:
        """MEASure:<quantity>?: configure for it, then READ?."""
        configure = self._configure(mode)

        def measure(query: bool, args: list[str]) -> str:
            configure(False, args)
            return nr3(self._measure())
        return measure

    # -- sense settings ---------------------------------------------------------------
    def _average(self, query: bool, args: list[str]) -> str | None:
        if query:
            word = optional_arg(args)
            value = self.averaging if word is None else AVERAGING_LIMITS.word(word)
            if value is None:
                raise ScpiError(-224)
            return str(int(value))
        self.averaging = integer(one_arg(args), AVERAGING_LIMITS, exact=True)
        return None

    def _wavelength(self, query: bool, args: list[str]) -> str | None:
        limits = Limits(self.sensor.wavelength_min_nm, self.sensor.wavelength_max_nm)
        if query:
            return limits_query(args, limits, self.wavelength_nm)
        self.wavelength_nm = number(one_arg(args), limits, WAVELENGTH_UNITS)
        self.user_response = None  # the head's responsivity at the new wavelength
        return None

    def _beam(self, query: bool, args: list[str]) -> str | None:
        limits = Limits(0.01, 100.0, self.sensor.aperture_mm)
        if query:
            return limits_query(args, limits, self.beam_mm)
        self.beam_mm = number(one_arg(args), limits, LENGTH_UNITS)
        return None

    def _attenuation(self, query: bool, args: list[str]) -> str | None:
        if query:
            return limits_query(args, ATTENUATION_LIMITS, self.attenuation_db)
        self.attenuation_db = number(one_arg(args), ATTENUATION_LIMITS)
        return None

    def _response(self, query: bool, args: list[str]) -> str | None:
        limits = Limits(*RESPONSE_LIMITS, self.photodiode.responsivity_a_w(self.wavelength_nm))
        if query:
            return limits_query(args, limits, self._responsivity())
        value = number(one_arg(args), limits, RESPONSE_UNITS)
        self.user_response = None if value == limits.default else value
        return None

    def _zero(self, query: bool, args: list[str]) -> None:
        no_args(args)
        self.operation.pulse(OPER_CORR)
        self.photodiode.zero(self.wavelength_nm)

    def _range(self, scale: float | None, units: Mapping[str, float]) -> Callable:
        """A range setting in W (scale 1) or in A (scale None: the power ranges times the
        responsivity); setting one picks the smallest range holding it, autorange off."""
        def access(query: bool, args: list[str]) -> str | None:
            factor = scale or self._responsivity()
            ranges = self.photodiode.ranges_w
            if query:
                return limits_query(args, Limits(ranges[0] * factor, ranges[-1] * factor),
                                    self.range_w * factor)
            value = number(one_arg(args), Limits(0.0, ranges[-1] * factor), units)
            self.range_w = self.photodiode.range_for(value / factor)
            self.autorange = False
            return None
        return access

    def _reference_state(self, quantity: str) -> Callable:
        """The delta mode's switch (SENS:POW:REF:STAT, SENS:CURR:REF:STAT)."""
        return flag_setting(lambda: self.references[quantity][1],
                            lambda on: self.references[quantity].__setitem__(1, on))

    def _reference(self, quantity: str) -> Callable:
        """The delta mode's reference (W or A; 0 to the top range, default 0)."""
        def access(query: bool, args: list[str]) -> str | None:
            factor = 1.0 if quantity == "POW" else self._responsivity()
            limits = Limits(0.0, self.photodiode.ranges_w[-1] * factor, 0.0)
            units = POWER_UNITS if quantity == "POW" else CURRENT_UNITS
            if query:
                return limits_query(args, limits, self.references[quantity][0])
            self.references[quantity][0] = number(one_arg(args), limits, units)
            return None
        return access

    def _unit(self, query: bool, args: list[str]) -> str | None:
        if query:
            no_args(args)
            return self.power_unit
        self.power_unit = choice(one_arg(args), ("W", "DBM"))
        return None


def _dbm(power_w: float) -> float:
    """Power in dBm (SCPI's negative infinity for no power)."""
    return 10.0 * math.log10(power_w / 1e-3) if power_w > 0 else SCPI_NINF
