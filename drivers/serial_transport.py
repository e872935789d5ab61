"""Line-oriented transport over a byte link (a serial port or a VISA resource) with bounded,
named timeouts and safe retries.

Protocol drivers send a line and read a reply line through it. Only queries are retried
(after a timeout or a garbled reply); a command that changes the device's state is sent
exactly once and its outcome is re-read by the driver instead. The link (drivers.byte_link:
pyserial's port or PyVISA's resource, opened by drivers.open_link) moves the bytes; every
failure of the link itself becomes a SerialPortError naming the port or the resource, so
callers see only DriverError subclasses. The port or resource is held (drivers.port_lock)
from before it opens until close: one another process holds is PortInUse, the line untouched.

A reply that missed its timeout may still arrive, after the next query has been sent, and
would be read as that query's answer (a power reading taken at the previous stage position).
Which request a line answers is decided by drivers.reply_sync (this module only reads and
writes): after a timeout the line is out of step, and before its next exchange the transport
sends the driver's sync query, whose answer no other exchange produces, and drops the lines
before that answer (the device answers in order, so whatever was late has come out by then).
A garbled line that arrives in step, with nothing older unanswered, is the answer to the line
just sent, garbled.

Devices of a daisy chain share one transport (drivers.zaber): each names itself with every
exchange (`device=`), and the errors of that exchange name it.

Some devices also speak unprompted (a Zaber device's alerts). The driver declares such lines
(`is_unsolicited`): the transport never takes one for a reply, garbled or not, but hands it to
the reply machine as a unit that can answer nothing here (UnitKind.FOREIGN), so it neither
ends a wait nor puts the line out of step, and counts it (`unsolicited`).

Before each write the transport takes what has arrived: it came before the request, so it
answers nothing sent now. Its whole lines are dropped (the unsolicited ones counted); a part
line is kept, marked stale, until its terminator comes, and is then dropped whole (counted if
unsolicited). The reply machine sees neither: a stale line may be an earlier request's late
reply, which the machine then leaves unaccounted for until the sync reply. Cut at the write, a
part line's tail would pass for a line of its own: an alert's tail, which no longer starts with
`!`, for the reply; a late reply's tail for the next request's answer. A stale part line that
never ends (noise with no terminator) swallows the line it runs into, the reply: a timeout,
which the reply machine recovers from, rather than a wrong reply. Bytes still in a UART's FIFO
or a USB adaptor when the input is taken come after the write (tcflush does not drop them
either); a line they begin arrives whole and is sorted by its content (`is_unsolicited`) and by
the reply machine, as a late reply is.

Two device habits are the transport's to handle, each an option. A device that echoes every
line it is sent before it answers (the Cornerstone monochromator's RS-232 port: `echo`) has
the echo read right after the write and checked against the line sent: a garbled, cut or
missing echo ends the exchange as a garbled or lost reply (the line then out of step, since
the answer may still come), and an echo that came whole confirms that the device took a
silent command. A device whose reply is several lines ended by a prompt (the FW102C filter
wheel's echo, answer and `> `: `read_eol` the prompt) has the bytes between those lines
allowed inside one reply (`line_breaks`), so one request gets one reply unit.
"""

from __future__ import annotations

import re
import termios
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar, Unpack

from drivers.base import DeviceTimeout, DriverError, ProtocolError
from drivers.byte_link import LineSettings, LinkFailure, LinkOptions
from drivers.open_link import open_byte_link
from drivers.reply_sync import Garbled, Reply, ReplySync, State, SyncReply, UnitKind
from drivers.serial_link import SerialLink
from drivers.visa_link import VisaLink

T = TypeVar("T")

PRINTABLE = bytes(range(0x20, 0x7F))


class SerialPortError(DriverError):
    """The link itself failed (could not be opened, or went away: unplugged USB adaptor, pty
    whose far side closed, instrument switched off); `port` is the serial port or VISA
    resource (`noun` says which), `action` what the driver was doing."""

    def __init__(self, device: str, port: str, action: str, cause: BaseException, noun: str):
        self.device, self.port, self.action, self.cause = device, port, action, cause
        what = "could not be opened" if action == "opening" else f"went away ({action})"
        super().__init__(f"{device}: {noun} {port} {what}: {_describe(cause)}")


def _text(body: bytes) -> str:
    """A line's bytes as text (a byte that is not ASCII as U+FFFD)."""
    return body.decode("ascii", errors="replace")


def _describe(exc: BaseException) -> str:
    """termios.error carries (errno, text) as a tuple; show it as OSError does."""
    if isinstance(exc, termios.error) and len(exc.args) == 2:
        return f"[Errno {exc.args[0]}] {exc.args[1]}"
    return str(exc) or type(exc).__name__


def strict_number_parser(pattern: str, expected: str) -> Callable[[str], float]:
    """A reader of numeric replies that must match pattern exactly: ASCII replies carry no
    checksum, so a dropped or garbled byte must break the shape (ProtocolError naming the
    expected form) rather than pass as another number."""
    shape = re.compile(pattern)

    def parse(text: str) -> float:
        if shape.fullmatch(text) is None:
            raise ProtocolError(f"garbled number {text!r} (expected {expected})")
        return float(text)

    return parse


@dataclass(frozen=True)
class SyncQuery:
    """A query whose reply no other exchange of the driver produces (`is_reply` tells it),
    sent to bring replies back in step after a timeout."""

    line: str
    is_reply: Callable[[str], bool]


def line_settings(name: str, baudrate: int, link: LinkOptions) -> LineSettings:
    """The line settings a device's driver asks for: its baud rate and the LinkOptions' line
    settings (their resource is none); a bad one is a ValueError naming the device."""
    options = {key: value for key, value in link.items() if key != "resource"}
    try:
        return LineSettings(baudrate, **options)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: {exc}") from None


class SerialLineTransport:
    """A device's line (a serial port, or a VISA resource given by `resource` instead of the
    port) exchanging ASCII lines, thread-safe (one exchange at a time).

    write_eol / read_eol: the line terminators sent and expected; timeout_s: how long a
    reply may take; retries: extra attempts a query gets after a timeout or garbled reply;
    sync: the driver's SyncQuery (None: only the stale input set aside before each write
    keeps a late reply out, if it has begun to arrive by then); is_unsolicited: tells a line the
    device sends unprompted, never a reply (None: every line may be one). baudrate and the
    LinkOptions' parity, stopbits, rtscts and xonxoff set a serial port's or an ASRL
    resource's line. `name` is the device its errors name, unless an exchange names another
    (`device=`: a device of a chain sharing the transport). echo: the device echoes every line
    before answering it (the module doc); line_breaks: bytes a reply may hold between its
    lines (a reply of several lines ended by a prompt).
    """

    def __init__(
        self,
        port: str | None = None,
        *,
        name: str,
        baudrate: int = 19200,
        write_eol: bytes = b"\r",
        read_eol: bytes = b"\r\n",
        timeout_s: float = 1.0,
        retries: int = 2,
        sync: SyncQuery | None = None,
        is_unsolicited: Callable[[str], bool] | None = None,
        echo: bool = False,
        line_breaks: bytes = b"",
        **link: Unpack[LinkOptions],
    ):
        if not timeout_s > 0:
            raise ValueError(f"{name}: timeout_s must be > 0, got {timeout_s!r}")
        if retries < 0:
            raise ValueError(f"{name}: retries must be >= 0, got {retries!r}")
        resource = link.get("resource")
        line = line_settings(name, baudrate, link)
        self.name = self._speaker = name
        self.port = port if resource is None else resource
        self.write_eol, self.read_eol = write_eol, read_eol
        self.timeout_s, self.retries = float(timeout_s), int(retries)
        self.sync, self.is_unsolicited = sync, is_unsolicited
        self.echo, self._allowed = echo, PRINTABLE + line_breaks
        self.replies = ReplySync()  # which request each line answers
        self.resyncs = 0  # sync queries answered (how often replies were out of step)
        self.unsolicited = 0  # unprompted lines read, set aside
        self._rx = bytearray()  # bytes read past the last line taken
        self._stale_head = False  # _rx begins with a line begun before the last write
        self.lock = threading.RLock()
        try:
            self.link, self._held = open_byte_link(port, resource, line, read_eol,
                                                   self.timeout_s, name)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
        except LinkFailure as exc:
            noun = (SerialLink if resource is None else VisaLink).noun  # no link to ask yet
            raise SerialPortError(name, self.port, "opening", exc.cause, noun) from exc.cause
        try:
            self._set_aside_stale_input()
        except BaseException:  # an interrupted open too: the port's hold goes with it
            self.close()
            raise

    @property
    def in_step(self) -> bool:
        """False from a missed reply until a sync query brings the replies back in step."""
        return self.replies.state is State.IN_STEP

    def line_counts(self) -> dict[str, int]:
        """What the line has seen so far: sync queries answered (`resyncs`) and unprompted
        lines set aside (`unsolicited`)."""
        return {"resyncs": self.resyncs, "unsolicited": self.unsolicited}

    # -- lifecycle --------------------------------------------------------------
    def close(self) -> None:
        """Close the link (idempotent; a link that has already gone away closes quietly,
        so closing in a `finally` never hides the error that ended the session); the port's
        hold is released."""
        try:
            self.link.close()
        finally:
            self._held.release()

    def __enter__(self) -> SerialLineTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- bytes ------------------------------------------------------------------
    def _port_error(self, action: str, failure: LinkFailure) -> DriverError:
        """A link failure during `action` as the DriverError callers see (a blocked write:
        DeviceTimeout, and whatever was being written may have partly gone out)."""
        if failure.write_timed_out:
            return DeviceTimeout(self._speaker, f"the port to take {action}", self.timeout_s)
        return SerialPortError(self._speaker, self.port, action, failure.cause, self.link.noun)

    def send(self, line: str, what: str | None = None, device: str | None = None) -> None:
        """Bring replies back in step if a reply was missed (DeviceTimeout naming `what`
        if that fails), set stale input aside, then write one line (terminator added) that
        gets no reply (a silent command)."""
        what = what or repr(line)
        with self.lock, self._for(device):
            try:
                self._in_step(what)
                self._write(line, request=False)
                if self.echo:
                    try:
                        self._take_echo(line, what, time.monotonic() + self.timeout_s)
                    except (DeviceTimeout, ProtocolError):
                        self.replies.send_request()  # the echo may still come: the line is
                        self.replies.timeout()  # out of step until a sync query's answer
                        raise
            finally:
                self._abandon_wait()

    def _take_echo(self, line: str, what: str, deadline: float) -> None:
        """Read the device's echo of the line just written: it must repeat the line, else
        ProtocolError (a garbled echo); DeviceTimeout if none comes by the deadline."""
        body = self._read_line(f"the echo of {what}", deadline)
        if body != line.encode("ascii"):
            raise ProtocolError(f"{self._speaker}: garbled echo of {what}: "
                                f"{body + self.read_eol!r}")

    def _in_step(self, what: str) -> None:
        """Out of step: send the sync query and drop every line before its reply, or, with no
        sync query, only trust the stale input set aside before the next write."""
        if self.replies.state is State.OUT_OF_STEP:
            if self.sync is None:
                self.replies.reset()
            else:
                self._resync(what)

    def _set_aside_stale_input(self) -> None:
        """Take what has arrived before a write: drop its whole lines, keep a part line as
        the stale head of `_rx` (dropped whole once its terminator comes, never cut)."""
        try:
            self._rx += self.link.take_input()
        except LinkFailure as exc:
            raise self._port_error("discarding stale input", exc) from exc.cause
        *lines, part = bytes(self._rx).split(self.read_eol)
        for body in lines:
            self._count_if_unsolicited(_text(body))
        self._rx[:] = part
        self._stale_head = bool(part)

    def _count_if_unsolicited(self, text: str) -> bool:
        """Whether the driver declares the line one its device sends unprompted; counted if so."""
        if self.is_unsolicited is None or not self.is_unsolicited(text):
            return False
        self.unsolicited += 1
        return True

    def _write(self, line: str, request: bool) -> None:
        """Write a line; request: its reply is awaited (the machine is told first)."""
        data = line.encode("ascii") + self.write_eol
        self._set_aside_stale_input()
        if request:
            self.replies.send_request(sync_shaped=self.sync is not None and
                                      line == self.sync.line)
        try:
            self.link.write(data)
        except LinkFailure as exc:
            if exc.write_timed_out and not self.replies.awaiting:
                self.replies.send_request()  # part of a silent line went out: it may be
                self.replies.timeout()  # answered after all (an error, an echo)
            raise self._port_error(f"writing {line[:40]!r}{'...' if len(line) > 40 else ''}",
                                   exc) from exc.cause

    @contextmanager
    def longer_replies(self, extra_s: float) -> Iterator[None]:
        """Replies to the exchanges in the block are waited for extra_s longer than
        timeout_s (a reply the device takes that long over: an averaged reading); other
        threads' exchanges wait for the block, as they wait for any exchange."""
        with self.lock:
            base = self.timeout_s
            self.timeout_s = base + extra_s
            try:
                yield
            finally:
                self.timeout_s = base

    @contextmanager
    def _for(self, device: str | None) -> Iterator[None]:
        """Under the lock: the errors of an exchange name `device` (None: whoever the
        enclosing exchange names, else the transport's own name) until it ends."""
        outer = self._speaker
        self._speaker = device or outer
        try:
            yield
        finally:
            self._speaker = outer

    def _abandon_wait(self) -> None:
        """After an exchange: a wait cut short (the port lost, a signal) leaves its reply to
        come, like a timeout."""
        if self.replies.awaiting:
            self.replies.timeout()

    def _resync(self, what: str) -> None:
        """Send the sync query and read until the machine is in step (every line before the
        sync reply is late, garbled or not), asking again after the reply to an older sync
        query; DeviceTimeout, still out of step, if a reply does not come in time."""
        assert self.sync is not None
        why = (f"{what} (replies out of step after a timeout: no answer to the sync query "
               f"{self.sync.line!r})")
        try:
            while self.replies.awaiting or self.replies.state is State.OUT_OF_STEP:
                self.replies.send_sync()
                self._write(self.sync.line, request=False)
                deadline = time.monotonic() + self.timeout_s
                while type(self._next_unit(why, deadline)) is not SyncReply:
                    pass
        except DeviceTimeout:
            if self.replies.state is not State.IN_STEP:
                raise
            return  # the late replies came, only the sync reply did not
        self.resyncs += 1

    def _reply(self, what: str, deadline: float) -> str:
        """The reply to the line just sent, by the deadline: the next line the machine takes
        for it."""
        while True:
            event = self._next_unit(what, deadline)
            if type(event) is Reply:
                return event.unit
            if type(event) is Garbled:  # in step, a garbled line ends the wait
                raise event.unit

    def _next_unit(self, what: str, deadline: float):
        """Read one line and feed it to the machine (DeviceTimeout, the machine told, if none
        comes by the deadline); the event it is. A line the driver declares unsolicited is
        foreign, whatever its bytes."""
        try:
            body = self._read_line(what, deadline)
        except DeviceTimeout:
            self.replies.timeout()
            raise
        text = _text(body)
        if self._count_if_unsolicited(text):
            return self.replies.receive(UnitKind.FOREIGN, text)
        if body.translate(None, self._allowed):  # a byte left is not printable ASCII
            garbled = ProtocolError(f"{self._speaker}: garbled reply to {what}: "
                                    f"{body + self.read_eol!r}")
            return self.replies.receive(UnitKind.GARBLED, garbled)
        sync = self.sync
        kind = UnitKind.SYNC if sync is not None and sync.is_reply(text) else UnitKind.ANSWER
        return self.replies.receive(kind, text)

    def _read_line(self, what: str, deadline: float) -> bytes:
        """Read one line's bytes (terminator stripped) by the monotonic `deadline`.

        Reads whatever the link has within the time left (a serial port: what has arrived; a
        VISA resource: a line); bytes after the terminator are kept for the next line (and set
        aside by the next send: a line protocol sends one reply per request). The stale line
        `_rx` may begin with is dropped here (counted if unsolicited). Raises
        DeviceTimeout(what) when no complete line arrives in time (the reply may still come).
        """
        data, eol = self._rx, self.read_eol
        while True:
            try:
                while eol not in data:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise DeviceTimeout(self._speaker, what, self.timeout_s)
                    data += self.link.read(left)
            except LinkFailure as exc:
                raise self._port_error(f"reading the reply to {what}", exc) from exc.cause
            end = data.index(eol)
            body = bytes(data[:end])
            del data[: end + len(eol)]
            if not self._stale_head:
                return body
            self._stale_head = False  # begun before the request: it answers nothing awaited
            self._count_if_unsolicited(_text(body))

    def exchange(self, line: str, what: str | None = None, device: str | None = None) -> str:
        """Send a line and read its reply once (no retry: for state-changing commands)."""
        what = what or repr(line)
        with self.lock, self._for(device):
            try:
                self._in_step(what)
                self._write(line, request=True)
                deadline = time.monotonic() + self.timeout_s
                if self.echo:
                    self._take_echo(line, what, deadline)
                return self._reply(what, deadline)
            finally:
                self._abandon_wait()

    def query(
        self,
        line: str,
        parse: Callable[[str], T],
        what: str | None = None,
        device: str | None = None,
    ) -> T:
        """Send a query and parse its reply, retrying after a timeout or garbled reply.

        parse raises ProtocolError for a reply it cannot read (retried) or DeviceError for
        a device error (not retried). After 1 + retries failed attempts the last
        DeviceTimeout / ProtocolError is raised.
        """
        what = what or repr(line)
        last: DriverError | None = None
        with self.lock, self._for(device):
            for _ in range(1 + self.retries):
                try:
                    return parse(self.exchange(line, what))
                except (DeviceTimeout, ProtocolError) as exc:
                    last = exc
        assert last is not None
        raise last
