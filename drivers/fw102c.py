"""Driver for the Thorlabs FW102C / FW212C motorised filter wheel (serial, 115200 baud 8N1).

From the FW102C manual (Rev H, 5.2.3 Keywords): lower-case `keyword=argument` commands and
`keyword?` queries ended by CR. The wheel echoes each line, answers a query on the next line
and then shows its prompt `> `, so one request gets one reply `echo CR [answer CR] > `: the
transport reads up to the prompt (`read_eol` CR `> `, the CR between echo and answer allowed
inside the reply). The echo must repeat the request and the answer must have its shape (a
position's digits), else the reply is garbled. The one dropped byte that keeps that shape is
a digit of position 10, 11 or 12 of a 12-position wheel (read as 1 or 2), so on such a wheel
a reply of 1 or 2 is asked twice more and the two must agree (drivers.agreed_read).
`Command error CMD_NOT_DEFINED` / `CMD_ARG_INVALID` in place of an answer is a DeviceError.

Queries are retried after a timeout or a garbled reply; `pos=n` is sent once
(drivers.lost_reply), and when its reply is lost the position read back settles it. The wheel
answers a move when it is in place, so a move's reply is waited for as long as a half turn
takes at the slow speed, beside the reply timeout. After a timeout `*idn?` (whose answer no
other request has) brings late replies back in step.

The wheel selects wavelengths through its filters: `filters` maps a position to the filter
there (centre wavelength and bandwidth, nm, from the instrument config); selecting a
wavelength turns to the one filter centred on it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from typing import NamedTuple, TypeVar, Unpack

from drivers.agreed_read import agreed
from drivers.base import DeviceError, DriverError, ProtocolError
from drivers.byte_link import LinkOptions
from drivers.lost_reply import not_resent, sent_once
from drivers.serial_transport import SerialLineTransport, SyncQuery

PROMPT = b"\r> "
ERROR_PREFIX = "Command error "
SLOWEST_HALF_TURN_S = 6.0  # how long the wheel may take to answer a move (slow speed)
SPEEDS = {"slow": 0, "high": 1}
_DIGITS = re.compile(r"\d{1,2}")
_ERRORS = {"CMD_NOT_DEFINED": "no such command or query",
           "CMD_ARG_INVALID": "argument wrong or out of range"}


T = TypeVar("T")


class Filter(NamedTuple):
    """The filter at one wheel position: its centre wavelength and passband width, nm (a
    config gives it as the triple)."""

    position: int
    centre_nm: float
    bandwidth_nm: float


def answer_of(request: str, reply: str) -> str | None:
    """The answer in a reply to `request` (None for a command's, which has none): the echo
    must repeat the request (ProtocolError otherwise); an error line is a DeviceError (its
    code is the manual's CMD_... name)."""
    echo, *rest = reply.split("\r")
    if echo != request or len(rest) > 1:
        raise ProtocolError(f"garbled reply to {request!r}: {reply!r}")
    answer = rest[0] if rest else None
    if answer is not None and answer.startswith(ERROR_PREFIX):
        code = answer.removeprefix(ERROR_PREFIX)
        raise DeviceError("fw102c", code, _ERRORS.get(code, answer))
    return answer


def text(answer: str | None) -> str:
    """A query's answer as it is (ProtocolError when the reply has none)."""
    if not answer:
        raise ProtocolError("no answer")
    return answer


def integer(answer: str | None) -> int:
    """A setting's or position's digits (ProtocolError for any other shape)."""
    if answer is None or _DIGITS.fullmatch(answer) is None:
        raise ProtocolError(f"garbled number {answer!r}")
    return int(answer)


class Fw102cWheel:
    """An FW102C (6 positions) or FW212C (12) on a serial port (or a VISA resource: LinkOptions)
    as a WavelengthSelector.

    filters: the filters in the wheel (Filter, or (position, centre_nm, bandwidth_nm));
    positions: the wheel type the config expects (the wheel's pcount must agree); speed:
    "high" or "slow", set when it opens; move_s: how much longer than timeout_s a move's reply
    may take (default: a half turn at the slow speed).
    """

    def __init__(self, port: str | None = None, *, filters: Iterable[tuple[int, float, float]],
                 positions: int = 6, speed: str = "high", move_s: float = SLOWEST_HALF_TURN_S,
                 name: str = "fw102c", baudrate: int = 115200, timeout_s: float = 1.0,
                 retries: int = 2, **link: Unpack[LinkOptions]):
        self.name, self.move_s = name, float(move_s)
        self.count = positions  # the wheel's positions, as its pcount? tells once it opens
        self.filters = {int(entry[0]): Filter(*entry) for entry in filters}
        if not self.filters:
            raise ValueError(f"{name}: no filters given")
        if speed not in SPEEDS:
            raise ValueError(f"{name}: speed must be one of {', '.join(SPEEDS)}, got {speed!r}")
        self.idn: str | None = None
        self.transport = SerialLineTransport(
            port, name=name, baudrate=baudrate, write_eol=b"\r", read_eol=PROMPT,
            line_breaks=b"\r", timeout_s=timeout_s, retries=retries,
            sync=SyncQuery("*idn?", self._is_idn), **link)
        try:
            self.idn = self.query("*idn?", text)
            self._check_wheel(positions)
            self.command(f"speed={SPEEDS[speed]}", lambda: self.query("speed?") == SPEEDS[speed])
        except BaseException:
            self.close()
            raise

    def _is_idn(self, reply: str) -> bool:
        """The reply to *idn? (the sync query): once known, exactly it (before, while *idn? is
        first asked, any reply echoing it)."""
        if self.idn is None:
            return reply.startswith("*idn?\r")
        return reply == f"*idn?\r{self.idn}"

    def _check_wheel(self, positions: int) -> None:
        self.count = count = self.query("pcount?")
        if count != positions:
            raise DriverError(f"{self.name}: the wheel has {count} positions (pcount?), the "
                              f"config says {positions}")
        beyond = sorted(p for p in self.filters if not 1 <= p <= count)
        if beyond:
            raise DriverError(f"{self.name}: a filter at position {beyond[0]}, beyond the "
                              f"wheel's {count} positions")

    # -- exchanges --------------------------------------------------------------
    def query(self, request: str, read: Callable[[str | None], T] = integer) -> T:
        """Ask a query (retried after a timeout or a garbled reply); its answer read by
        `read` (a ProtocolError from it is a garbled reply, asked again)."""
        def parse(reply: str) -> T:
            answer = self._answer(request, reply)
            try:
                return read(answer)
            except ProtocolError as exc:
                raise ProtocolError(f"{self.name}: reply to {request!r}: {exc}") from None

        return self.transport.query(request, parse)

    def _answer(self, request: str, reply: str) -> str | None:
        try:
            return answer_of(request, reply)
        except DeviceError as exc:
            raise DeviceError(self.name, exc.code, exc.text) from None
        except ProtocolError as exc:
            raise ProtocolError(f"{self.name}: {exc}") from None

    def command(self, request: str, taken: Callable[[], bool]) -> None:
        """Send a command once; if its reply is lost or garbled, taken() reads the wheel back
        (DriverError when it did not take it: never re-sent)."""
        sent_once(lambda: self._answer(request, self.transport.exchange(request)), taken,
                  not_resent(self.name, request))

    # -- the wheel --------------------------------------------------------------
    def position(self) -> int:
        """pos?: the position the wheel is at (on a 12-position wheel a 1 or 2, which a
        dropped digit of 10-12 also gives, asked twice more: ProtocolError if they differ)."""
        found = self.query("pos?")
        if self.count > 9 and found < self.count - 9:
            return agreed(lambda: self.query("pos?"), self.name, "pos?", reads=2)
        return found

    def move_to_position(self, position: int) -> None:
        """pos=n: turn to position n; returns once the wheel is there (it answers then)."""
        if position not in self.filters:
            raise ValueError(f"{self.name}: no filter at position {position!r} (filters at "
                             f"{', '.join(map(str, sorted(self.filters)))})")
        with self.transport.longer_replies(self.move_s):
            self.command(f"pos={position}", lambda: self.position() == position)

    def filter_for(self, wavelength_nm: float) -> Filter:
        """The filter centred on wavelength_nm (ValueError naming the centres there are)."""
        for found in self.filters.values():
            if abs(found.centre_nm - wavelength_nm) <= 1e-9 * max(1.0, wavelength_nm):
                return found
        centres = ", ".join(f"{f.centre_nm:g}" for f in self.filters.values())
        raise ValueError(f"{self.name}: no filter centred on {wavelength_nm:g} nm (filters: "
                         f"{centres} nm)")

    # -- WavelengthSelector -----------------------------------------------------
    def wavelengths_nm(self) -> tuple[float, ...]:
        """The wavelengths the wheel selects: its filters' centres, increasing."""
        return tuple(sorted(f.centre_nm for f in self.filters.values()))

    def move_to_nm(self, wavelength_nm: float) -> None:
        """Turn to the filter centred on wavelength_nm (blocks while the wheel turns)."""
        self.move_to_position(self.filter_for(wavelength_nm).position)

    def wait(self, timeout_s: float) -> float:
        """The wheel answers a move once it is there: the wavelength it selects now."""
        return self.wavelength_nm()

    def wavelength_nm(self) -> float:
        """The centre wavelength of the filter in the beam (DriverError: no filter there)."""
        return self.current_filter().centre_nm

    def bandwidth_nm(self) -> float:
        """The passband width of the filter in the beam."""
        return self.current_filter().bandwidth_nm

    def current_filter(self) -> Filter:
        """The filter at the wheel's position (DriverError if the config names none there)."""
        position = self.position()
        if position not in self.filters:
            raise DriverError(f"{self.name}: the wheel is at position {position}, where the "
                              "config names no filter")
        return self.filters[position]

    def identity(self) -> dict[str, str]:
        """The wheel's *idn? answer (model and firmware version)."""
        return {"idn": self.idn or ""}

    def line_counts(self) -> dict[str, int]:
        """What the line has seen (drivers.base.LineCounts)."""
        return self.transport.line_counts()

    def close(self) -> None:
        """Close the port."""
        self.transport.close()
