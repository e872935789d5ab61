"""IEEE 488.2 status reporting with SCPI status registers, for the instrument emulators.

A `StatusRegister` is a SCPI register group (SCPI-99 vol. 1, ch. 9; vol. 2, ch. 20): a
condition register, transition filters (PTRansition: a 0 -> 1 change of a condition bit
sets its event bit; NTRansition: a 1 -> 0 change does), a latched event register cleared by
reading it, and an enable mask whose AND with the events is the group's summary bit in the
status byte. `StatusModel` adds the Standard Event Status Register (ESR) with its enable (ESE),
the Service Request Enable (SRE) and the status byte (*STB?), whose bit 6 is the master
summary: (status byte AND SRE) over bits 0-5 and 7 (IEEE 488.2, 11.2 and 11.5), and the SCPI
error queue (SCPI-99 vol. 2, 21.8) whose non-empty state is a status byte bit.
`StatusModel.common_commands` gives the IEEE 488.2 status commands with SYSTem:ERRor and
STATus:PRESet; `register_commands` the STATus subsystem's commands for a set of register groups.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping

from sim.devices.scpi_program import SCPI_ERRORS, Limits, integer, no_args, one_arg

REGISTER_MASK = 0x7FFF  # SCPI: bit 15 of a 16-bit status register is always 0
REGISTER_SETTING = (Limits(0, 65535), REGISTER_MASK)  # a register's mask: 0-65535, bit 15 reads 0
BYTE_LIMITS = Limits(0, 255)  # *ESE, *SRE: 8-bit enable registers
QUEUE_OVERFLOW = -350

# Standard Event Status Register bits (IEEE 488.2, 11.5.1.1)
ESR_OPC = 0x01  # operation complete (*OPC)
ESR_QYE = 0x04  # query error (-400 ... -499)
ESR_DDE = 0x08  # device-dependent error (-300 ... -399)
ESR_EXE = 0x10  # execution error (-200 ... -299)
ESR_CME = 0x20  # command error (-100 ... -199)
ESR_PON = 0x80  # power on
STB_MAV = 0x10  # message available
STB_ESB = 0x20  # event status bit: ESR AND ESE is not zero
STB_MSS = 0x40  # master summary status (RQS)


def error_class_bit(code: int) -> int:
    """The ESR bit a SCPI error code sets (its class by hundreds; 0 and positive: none)."""
    for low, bit in ((-199, ESR_CME), (-299, ESR_EXE), (-399, ESR_DDE), (-499, ESR_QYE)):
        if low <= code <= low + 99:
            return bit
    return 0


class StatusRegister:
    """A SCPI status register group (condition, PTR / NTR filters, event, enable)."""

    def __init__(self) -> None:
        self.condition = 0
        self.event = 0
        self.preset()

    def preset(self) -> None:
        """STATus:PRESet: nothing enabled, every rising edge latched, no falling one."""
        self.enable, self.ptr, self.ntr = 0, REGISTER_MASK, 0

    def set_condition(self, bits: int) -> None:
        """The condition register becomes `bits`; the edges the filters pass set events."""
        bits &= REGISTER_MASK
        rising, falling = bits & ~self.condition, self.condition & ~bits
        self.event |= (rising & self.ptr) | (falling & self.ntr)
        self.condition = bits

    def assign(self, bits: int, on: bool) -> None:
        """Set (on) or clear the condition bits `bits`, the others kept."""
        self.set_condition(self.condition | bits if on else self.condition & ~bits)

    def pulse(self, bits: int) -> None:
        """A state that came and went within one command (a measurement, a zeroing): the
        condition bits rise and fall again, leaving the events their edges pass."""
        before = self.condition
        self.set_condition(before | bits)
        self.set_condition(before)

    def read_event(self) -> int:
        """[:EVENt]?: the latched events, cleared by the reading."""
        value, self.event = self.event, 0
        return value

    @property
    def summary(self) -> bool:
        """The group's summary bit: an enabled event is latched."""
        return bool(self.event & self.enable)


class StatusModel:
    """The status byte with its SCPI register groups (`groups`: status byte bit -> the group
    it summarises), the Standard Event Status Register, the enables and the error queue
    (`error_queue_depth` entries; `error_queue_bit`: its status byte bit while not empty)."""

    def __init__(self, groups: Mapping[int, StatusRegister], error_queue_bit: int,
                 error_queue_depth: int):
        self.groups = dict(groups)
        self.esr = ESR_PON
        self.ese = 0
        self.sre = 0
        self.errors: deque[int] = deque()
        self.error_queue_bit = error_queue_bit
        self.error_queue_depth = error_queue_depth

    def push_error(self, code: int) -> None:
        """Queue a SCPI error (when full, the newest entry becomes -350 Queue overflow); the
        error's class sets its Standard Event Status bit."""
        self.record(error_class_bit(code))
        if len(self.errors) >= self.error_queue_depth:
            self.errors[-1] = QUEUE_OVERFLOW
        else:
            self.errors.append(code)

    def next_error(self) -> str:
        """SYSTem:ERRor[:NEXT]?: the oldest queued error as `code,"message"` (0 when none)."""
        code = self.errors.popleft() if self.errors else 0
        return f'{code},"{SCPI_ERRORS[code]}"'

    def record(self, bits: int) -> None:
        """Set Standard Event Status Register bits (an error's class, OPC)."""
        self.esr |= bits & 0xFF

    def read_esr(self) -> int:
        """*ESR?: the Standard Event Status Register, cleared by the reading."""
        value, self.esr = self.esr, 0
        return value

    def status_byte(self, message_available: bool) -> int:
        """*STB?: every summary bit (the error queue's while errors are queued; MAV while an
        answer waits to be sent), with the master summary in bit 6."""
        stb = sum(bit for bit, group in self.groups.items() if group.summary)
        stb |= self.error_queue_bit if self.errors else 0
        stb |= STB_MAV if message_available else 0
        stb |= STB_ESB if self.esr & self.ese else 0
        return stb | (STB_MSS if stb & self.sre & ~STB_MSS else 0)

    def clear(self) -> None:
        """*CLS: the error queue and every event register cleared (ESR and the groups');
        enables stay."""
        self.errors.clear()
        self.esr = 0
        for group in self.groups.values():
            group.event = 0

    def preset(self) -> None:
        """STATus:PRESet: every group's enable and transition filters to their defaults."""
        for group in self.groups.values():
            group.preset()

    def common_commands(self, message_available: Callable[[], bool]) -> list[tuple]:
        """The IEEE 488.2 status commands (*CLS, *ESE, *SRE, *ESR?, *STB?, and *OPC / *WAI
        for an instrument that completes each command before reading the next), the error
        queue's SYSTem:ERRor[:NEXT]? and :COUNt? and STATus:PRESet, as register_commands
        gives them; `message_available` tells *STB? whether an answer waits (MAV)."""
        return [
            ("*CLS", False, True, lambda q, a: no_args(a) or self.clear()),
            ("*OPC", True, True, self._opc),
            ("*WAI", False, True, lambda q, a: no_args(a)),
            ("*ESE", True, True, _mask(self, "ese", BYTE_LIMITS, 0xFF)),
            # SRE's bit 6 is not settable (IEEE 488.2, 11.3.2)
            ("*SRE", True, True, _mask(self, "sre", BYTE_LIMITS, 0xFF & ~STB_MSS)),
            ("*ESR", True, False, _reader(self.read_esr)),
            ("*STB", True, False, _reader(lambda: self.status_byte(message_available()))),
            ("SYSTem:ERRor[:NEXT]", True, False, lambda q, a: no_args(a) or self.next_error()),
            ("SYSTem:ERRor:COUNt", True, False, _reader(lambda: len(self.errors))),
            ("STATus:PRESet", False, True, lambda q, a: no_args(a) or self.preset()),
        ]

    def _opc(self, query: bool, args: list[str]) -> str | None:
        """*OPC sets the OPC event bit, *OPC? answers 1 (every command is complete)."""
        no_args(args)
        if query:
            return "1"
        self.record(ESR_OPC)
        return None


def register_commands(groups: Mapping[str, StatusRegister]) -> list[tuple]:
    """The STATus subsystem's commands for named register groups (`groups`: 'OPERation' ->
    its register): [:EVENt]?, :CONDition?, :ENABle, :PTRansition, :NTRansition (set and
    query), as (header pattern, query allowed, set allowed, action(query, args))."""
    table = []
    for name, group in groups.items():
        root = f"STATus:{name}"
        table += [
            (f"{root}[:EVENt]", True, False, _reader(group.read_event)),
            (f"{root}:CONDition", True, False, _reader(lambda g=group: g.condition)),
            (f"{root}:ENABle", True, True, _mask(group, "enable", *REGISTER_SETTING)),
            (f"{root}:PTRansition", True, True, _mask(group, "ptr", *REGISTER_SETTING)),
            (f"{root}:NTRansition", True, True, _mask(group, "ntr", *REGISTER_SETTING)),
        ]
    return table


def _reader(value: Callable[[], int]) -> Callable[[bool, list[str]], str]:
    def query(_: bool, args: list[str]) -> str:
        no_args(args)
        return str(value())
    return query


def _mask(owner: object, field: str, limits: Limits, bits: int
          ) -> Callable[[bool, list[str]], str | None]:
    """A mask setting held in `owner.field` (<NRf> or non-decimal numeric within `limits`;
    the bits outside `bits` read 0)."""
    def access(query: bool, args: list[str]) -> str | None:
        if query:
            no_args(args)
            return str(getattr(owner, field))
        setattr(owner, field, integer(one_arg(args), limits) & bits)
        return None
    return access
