"""The PM100 console's system settings that have nothing to do with the light: line
frequency, calibration message, and the front-panel functions a console model has (display
brightness and contrast, clock, beeper), as SCPI commands for the emulator's table.

These settings survive *RST (IEEE 488.2 leaves system settings to the instrument; a console
keeps its clock and line frequency). The clock runs on `wall` (epoch seconds) from the date
and time last set.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Mapping

from sim.devices.pm100_models import Console
from sim.devices.scpi_program import (
    Limits,
    ScpiError,
    attribute_flag,
    integer,
    limits_query,
    no_args,
    number,
    one_arg,
)

DISPLAY_LIMITS = {"BRIGhtness": Limits(0.0, 1.0, 1.0), "CONTrast": Limits(0.0, 1.0, 0.5)}
CALIBRATION = "01-Jan-2026"  # CALibration:STRing?: the console's calibration message
LINE_FREQUENCIES = (50, 60)
DATE_FIELDS = {"year": Limits(2000, 2099), "month": Limits(1, 12), "day": Limits(1, 31)}
TIME_FIELDS = {"hour": Limits(0, 23), "minute": Limits(0, 59), "second": Limits(0, 59)}


class Panel:
    """A console's system settings and its SCPI commands."""

    def __init__(self, console: Console, wall: Callable[[], float]):
        self.console, self.wall = console, wall
        self.line_frequency_hz = 50
        self.display = {name: DISPLAY_LIMITS[name].default for name in console.display}
        self.beeper_on = True
        self.beeps = 0
        self._clock_offset_s = 0.0

    def commands(self) -> list[tuple]:
        """(header pattern, query allowed, set allowed, action) of the console's commands."""
        table = [
            ("SYSTem:LFRequency", True, True, self._line_frequency),
            ("CALibration:STRing", True, False, lambda q, a: no_args(a) or f'"{CALIBRATION}"'),
        ]
        table += [(f"DISPlay:{name}", True, True, self._display(name)) for name in self.display]
        if self.console.clock:
            table += [("SYSTem:DATE", True, True, self._clock(DATE_FIELDS)),
                      ("SYSTem:TIME", True, True, self._clock(TIME_FIELDS))]
        if self.console.beeper:
            table += [("SYSTem:BEEPer[:IMMediate]", False, True, self._beep),
                      ("SYSTem:BEEPer:STATe", True, True, attribute_flag(self, "beeper_on"))]
        return table

    def _line_frequency(self, query: bool, args: list[str]) -> str | None:
        if query:
            no_args(args)
            return str(self.line_frequency_hz)
        value = integer(one_arg(args), Limits(0, 1000), exact=True)
        if value not in LINE_FREQUENCIES:
            raise ScpiError(-224)
        self.line_frequency_hz = value
        return None

    def _display(self, name: str) -> Callable:
        limits = DISPLAY_LIMITS[name]

        def access(query: bool, args: list[str]) -> str | None:
            if query:
                return limits_query(args, limits, self.display[name])
            self.display[name] = number(one_arg(args), limits)
            return None
        return access

    # -- clock ------------------------------------------------------------------------
    def now(self) -> dt.datetime:
        """The console clock's date and time now."""
        return dt.datetime.fromtimestamp(self.wall() + self._clock_offset_s)

    def _set_clock(self, when: dt.datetime) -> None:
        self._clock_offset_s = when.timestamp() - self.wall()

    def _clock(self, fields: Mapping[str, Limits]) -> Callable:
        """SYSTem:DATE (year, month, day) or :TIME (hour, minute, second): three NR1 fields
        set together (-222 for a day the month does not have) and answered together."""
        def access(query: bool, args: list[str]) -> str | None:
            now = self.now()
            if query:
                no_args(args)
                return ",".join(str(getattr(now, name)) for name in fields)
            if len(args) != len(fields):
                raise ScpiError(-109 if len(args) < len(fields) else -108)
            values = {name: integer(arg, limits, exact=True)
                      for (name, limits), arg in zip(fields.items(), args, strict=True)}
            try:
                self._set_clock(now.replace(**values))
            except ValueError:
                raise ScpiError(-222) from None
            return None
        return access

    # -- beeper -----------------------------------------------------------------------
    def _beep(self, query: bool, args: list[str]) -> None:
        no_args(args)
        self.beeps += 1 if self.beeper_on else 0
