"""Which request a reply answers: one sans-I/O state machine (in the manner of h11) shared by
the serial line transport and the Modbus link, which do the I/O around it.

A device answers in order, but a reply may be lost, garbled, or late (past its timeout, after the
next request has gone out). The shell tells the machine what it sends (requests, sync queries)
and feeds it each unit that arrives (a reply line, a Modbus frame), sorted by the protocol into a
`UnitKind`; the machine answers with a typed event (Reply, LateReply, SyncReply, Garbled) and
keeps the state of the line. It holds the items sent whose replies are not yet accounted for, in
order, and attributes each unit to the earliest item it could answer: it may under-count progress
(then it stays out of step a little longer) but it never takes a reply for a later request than
the one it answers, so a late reply is never a later request's answer.

States (`TRANSITIONS` is the whole table):
- IN_STEP: no request's reply can still arrive but the one awaited now (if any).
- OUT_OF_STEP: an earlier request's reply may still come (syncs pending): a sync query must go
  out before the next request.
- RESYNCING: a sync query is out and its reply awaited; what comes before it is late.
"""

from __future__ import annotations

from collections import deque
from enum import Enum


class State(Enum):
    """Whether a unit that arrives can be taken as the answer to the request just sent."""

    IN_STEP = "in step"
    OUT_OF_STEP = "out of step"
    RESYNCING = "resyncing"

    __hash__ = object.__hash__  # a singleton's identity (Enum hashes its name in Python)


class UnitKind(Enum):
    """What the protocol can tell about a unit from its content alone."""

    ANSWER = "answer"  # shaped like the answer to a request
    SYNC = "sync"  # shaped like the answer to a sync query (a request that is the sync query
    # itself gets one too)
    FOREIGN = "foreign"  # a well-formed unit that can answer nothing here (another function,
    # transaction id or unit)
    GARBLED = "garbled"  # one unit, unreadable (a line with bytes that are not printable ASCII)


class Input(Enum):
    """What moves the machine: the shell's actions, and the events units turn into."""

    SEND_REQUEST = "send request"
    SEND_SYNC = "send sync"
    REPLY = "reply"
    LATE_REPLY = "late reply"
    SYNC_REPLY = "sync reply"
    GARBLED = "garbled"
    TIMEOUT = "timeout"

    __hash__ = object.__hash__  # looked up on every send and reply, as State is


class SyncMisuse(RuntimeError):
    """The shell did something the state does not allow (a request while out of step, a sync
    while in step, a timeout with nothing awaited): a bug in the shell, not a line fault."""


class Event:
    """What a unit turned out to be; `unit` is the line or frame itself."""

    __slots__ = ("unit",)
    input: Input

    def __init__(self, unit: object):
        self.unit = unit

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.unit!r})"


class Reply(Event):
    """The answer to the request awaited now."""

    __slots__ = ()
    input = Input.REPLY


class LateReply(Event):
    """The answer to an earlier request, or a unit nothing sent can explain: dropped."""

    __slots__ = ()
    input = Input.LATE_REPLY


class SyncReply(Event):
    """The answer to a sync query (the one awaited, or one that timed out earlier)."""

    __slots__ = ()
    input = Input.SYNC_REPLY


class Garbled(Event):
    """An unreadable unit: the awaited request's answer if nothing sent earlier is still
    unanswered, else of unknown origin (the line is then out of step)."""

    __slots__ = ()
    input = Input.GARBLED


_IN, _OUT, _RESYNC = State.IN_STEP, State.OUT_OF_STEP, State.RESYNCING
_SEND_REQUEST = Input.SEND_REQUEST

# (state, input) -> (next state when no request but the awaited one is unanswered, next state
# when one is). A pair missing from the table is a SyncMisuse.
TRANSITIONS: dict[tuple[State, Input], tuple[State, State]] = {
    (_IN, Input.SEND_REQUEST): (_IN, _IN),
    (_IN, Input.REPLY): (_IN, _IN),
    (_IN, Input.LATE_REPLY): (_IN, _IN),
    (_IN, Input.SYNC_REPLY): (_IN, _IN),
    (_IN, Input.GARBLED): (_IN, _OUT),
    (_IN, Input.TIMEOUT): (_IN, _OUT),
    (_OUT, Input.SEND_SYNC): (_RESYNC, _RESYNC),
    (_OUT, Input.LATE_REPLY): (_IN, _OUT),
    (_OUT, Input.SYNC_REPLY): (_IN, _OUT),
    (_OUT, Input.GARBLED): (_IN, _OUT),
    (_RESYNC, Input.SEND_SYNC): (_RESYNC, _RESYNC),  # after an older sync query's reply
    (_RESYNC, Input.LATE_REPLY): (_RESYNC, _RESYNC),  # its own reply is still to come
    (_RESYNC, Input.SYNC_REPLY): (_IN, _RESYNC),
    (_RESYNC, Input.GARBLED): (_RESYNC, _RESYNC),
    (_RESYNC, Input.TIMEOUT): (_IN, _OUT),
}

# the table by state, then input (what _move looks up on every send and reply); and the
# members the hot paths compare with, bound once (an Enum member's class attribute is slow)
_NEXT = {state: {what: nxt for (row, what), nxt in TRANSITIONS.items() if row is state}
         for state in State}
_SYNC, _FOREIGN, _GARBLED = UnitKind.SYNC, UnitKind.FOREIGN, UnitKind.GARBLED


class _Item:
    """One thing sent whose reply is not yet accounted for, and the shape its reply has."""

    __slots__ = ("is_sync", "sync_shaped", "sync_id")

    def __init__(self, is_sync: bool, sync_shaped: bool, sync_id: object = None):
        self.is_sync, self.sync_shaped, self.sync_id = is_sync, sync_shaped, sync_id


class ReplySync:
    """The reply-synchronisation state of one line (the shell serialises calls to it).

    send_request / send_sync before writing; receive(kind, unit) for each unit read while
    `awaiting`; timeout() when the awaited reply did not come in time; reset() when the line
    itself was replaced (a new TCP connection: nothing sent before can arrive on it).
    """

    __slots__ = ("state", "_unanswered", "_requests", "_awaited")

    def __init__(self) -> None:
        self.state = State.IN_STEP
        self._unanswered: deque[_Item] = deque()  # sent, reply not accounted for, oldest first
        self._requests = 0  # how many of them are requests
        self._awaited: _Item | None = None  # the item whose reply ends the present wait

    @property
    def awaiting(self) -> bool:
        """True while a reply (to the request just sent, or to the sync query) is awaited."""
        return self._awaited is not None

    @property
    def unanswered(self) -> tuple[str, ...]:
        """The items sent whose replies are not accounted for, oldest first ("request" or
        "sync"): what a unit that arrives now may answer."""
        return tuple("sync" if item.is_sync else "request" for item in self._unanswered)

    # -- the shell's actions ------------------------------------------------------
    def send_request(self, sync_shaped: bool = False) -> None:
        """A request is about to be written; its reply is awaited. sync_shaped: the request is
        the sync query itself (sent for its answer), so its reply is SYNC-shaped."""
        if self._awaited is not None:
            raise SyncMisuse("a request sent while a reply is still awaited")
        self._move(_SEND_REQUEST)
        self._awaited = item = _Item(False, sync_shaped)
        self._unanswered.append(item)
        self._requests += 1

    def send_sync(self, sync_id: object = None) -> None:
        """A sync query is about to be written (sync_id: what tells its reply from the replies
        to other sync queries, if anything does); its reply is awaited."""
        self._move(Input.SEND_SYNC)
        self._awaited = item = _Item(True, True, sync_id)
        self._unanswered.append(item)

    def timeout(self) -> None:
        """The awaited reply did not come in time (it may still come)."""
        if self._awaited is None:
            raise SyncMisuse("a timeout with no reply awaited")
        self._awaited = None
        self._move(Input.TIMEOUT)

    def reset(self) -> None:
        """The line was replaced: nothing sent before can arrive any more."""
        self._unanswered.clear()
        self._requests = 0
        self._awaited = None
        self.state = State.IN_STEP

    # -- units ------------------------------------------------------------------
    def receive(self, kind: UnitKind, unit: object, sync_id: object = None) -> Event:
        """The event a unit is, the state moved by it. sync_id: for a SYNC unit, the id of the
        sync query it answers, if the unit shows it (else the earliest one that can be)."""
        found = self._attribute(kind, sync_id)
        if kind is _GARBLED:
            event: Event = Garbled(unit)
            if self.state is _IN:
                self._awaited = None  # the exchange is over either way
        elif found is None:
            event = LateReply(unit)
        elif found.is_sync:
            event = SyncReply(unit)
        elif found is self._awaited:
            event = Reply(unit)
            self._awaited = None
        else:
            event = LateReply(unit)
        self._move(event.input)
        return event

    def _attribute(self, kind: UnitKind, sync_id: object) -> _Item | None:
        """The earliest unanswered item the unit can answer, removed with every item before it
        (their replies have come or never will: replies come in order); None if there is none."""
        index = self._match(kind, sync_id)
        if index is None:
            return None
        queue = self._unanswered
        for _ in range(index + 1):
            item = queue.popleft()
            self._requests -= not item.is_sync
        return item

    def _match(self, kind: UnitKind, sync_id: object) -> int | None:
        """Where the earliest unanswered item the unit can answer is."""
        queue = self._unanswered
        if kind is _GARBLED:  # only the awaited request, when nothing is before it
            return 0 if queue and queue[0] is self._awaited and not queue[0].is_sync else None
        if kind is _FOREIGN:
            return None
        sync = kind is _SYNC
        for index, item in enumerate(queue):
            if item.sync_shaped is sync and (sync_id is None or item.sync_id == sync_id):
                return index
        return None

    def _move(self, what: Input) -> None:
        try:
            clear, waiting = _NEXT[self.state][what]
        except KeyError:
            raise SyncMisuse(f"{what.value} while {self.state.value}") from None
        awaited = self._awaited
        others = self._requests - (awaited is not None and not awaited.is_sync)
        self.state = waiting if others else clear
        if awaited is not None and awaited.is_sync and self.state is not _RESYNC:
            self._awaited = None  # the resync is over
