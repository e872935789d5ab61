"""The reply-synchronisation machine on its own (no transport): every state x input from a
table, then random interleavings of replies, late replies, garbage, losses and timeouts
against a simulated in-order device, checking that no reply is ever taken for the wrong
request, that in step means nothing late can still come, and that a sync brings the line
back in step."""

from collections import deque
from dataclasses import dataclass

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.reply_sync import (
    TRANSITIONS,
    Garbled,
    Input,
    LateReply,
    Reply,
    ReplySync,
    State,
    SyncMisuse,
    SyncReply,
    UnitKind,
)

IN, OUT, RESYNC = State.IN_STEP, State.OUT_OF_STEP, State.RESYNCING
R, S = "request", "sync"

# how each starting situation is reached: (action, argument) pairs
SETUPS = {
    "idle": [],
    "awaiting": [("send_request", None)],
    "awaiting behind a stale sync": [  # [S2, R]: S1's reply took the timed-out request along
        ("send_request", None), ("timeout", None), ("send_sync", "s1"), ("timeout", None),
        ("send_sync", "s2"), ("receive", UnitKind.SYNC), ("send_request", None)],
    "awaiting a sync-shaped answer": [("send_request", True)],
    "out of step": [("send_request", None), ("timeout", None)],
    "resyncing": [("send_request", None), ("timeout", None), ("send_sync", "s1")],
    "resyncing after an older sync": [
        ("send_request", None), ("timeout", None), ("send_sync", "s1"), ("timeout", None),
        ("send_sync", "s2")],
    "resyncing, the late reply in": [
        ("send_request", None), ("timeout", None), ("send_sync", "s1"),
        ("receive", UnitKind.ANSWER)],
    "resyncing behind a stale sync": [  # [S2, R, S3]
        ("send_request", None), ("timeout", None), ("send_sync", "s1"), ("timeout", None),
        ("send_sync", "s2"), ("receive", UnitKind.SYNC), ("send_request", None),
        ("timeout", None), ("send_sync", "s3")],
}

INPUTS = {
    "send request": ("send_request", None),
    "send sync": ("send_sync", "new"),
    "answer": ("receive", (UnitKind.ANSWER, None)),
    "sync reply, anonymous": ("receive", (UnitKind.SYNC, None)),
    "sync reply s1": ("receive", (UnitKind.SYNC, "s1")),
    "sync reply s2": ("receive", (UnitKind.SYNC, "s2")),
    "foreign": ("receive", (UnitKind.FOREIGN, None)),
    "garbled": ("receive", (UnitKind.GARBLED, None)),
    "timeout": ("timeout", None),
    "reset": ("reset", None),
}

MISUSE = "misuse"
# (setup, input) -> (event type or None, state after, unanswered after, awaiting after)
TABLE = {
    "idle": {
        "send request": (None, IN, (R,), True),
        "send sync": MISUSE,
        "answer": (LateReply, IN, (), False),
        "sync reply, anonymous": (LateReply, IN, (), False),
        "sync reply s1": (LateReply, IN, (), False),
        "sync reply s2": (LateReply, IN, (), False),
        "foreign": (LateReply, IN, (), False),
        "garbled": (Garbled, IN, (), False),
        "timeout": MISUSE,
        "reset": (None, IN, (), False),
    },
    "awaiting": {
        "send request": MISUSE,
        "send sync": MISUSE,
        "answer": (Reply, IN, (), False),
        "sync reply, anonymous": (LateReply, IN, (R,), True),
        "sync reply s1": (LateReply, IN, (R,), True),
        "sync reply s2": (LateReply, IN, (R,), True),
        "foreign": (LateReply, IN, (R,), True),
        "garbled": (Garbled, IN, (), False),  # nothing older: the answer, garbled
        "timeout": (None, OUT, (R,), False),
        "reset": (None, IN, (), False),
    },
    "awaiting behind a stale sync": {
        "send request": MISUSE,
        "send sync": MISUSE,
        "answer": (Reply, IN, (), False),  # the stale sync's reply never came
        "sync reply, anonymous": (SyncReply, IN, (R,), True),
        "sync reply s1": (LateReply, IN, (S, R), True),  # s1 is accounted for already
        "sync reply s2": (SyncReply, IN, (R,), True),
        "foreign": (LateReply, IN, (S, R), True),
        "garbled": (Garbled, OUT, (S, R), False),  # the sync's or the request's: unknown
        "timeout": (None, OUT, (S, R), False),
        "reset": (None, IN, (), False),
    },
    "awaiting a sync-shaped answer": {
        "answer": (LateReply, IN, (R,), True),
        "sync reply, anonymous": (Reply, IN, (), False),
        "garbled": (Garbled, IN, (), False),
        "timeout": (None, OUT, (R,), False),
    },
    "out of step": {
        "send request": MISUSE,
        "send sync": (None, RESYNC, (R, S), True),
        "answer": (LateReply, IN, (), False),  # the late reply itself: nothing left to come
        "sync reply, anonymous": (LateReply, OUT, (R,), False),
        "sync reply s1": (LateReply, OUT, (R,), False),
        "sync reply s2": (LateReply, OUT, (R,), False),
        "foreign": (LateReply, OUT, (R,), False),
        "garbled": (Garbled, OUT, (R,), False),
        "timeout": MISUSE,
        "reset": (None, IN, (), False),
    },
    "resyncing": {
        "send request": MISUSE,
        "send sync": (None, RESYNC, (R, S, S), True),
        "answer": (LateReply, RESYNC, (S,), True),  # late; the sync's reply is still due
        "sync reply, anonymous": (SyncReply, IN, (), False),
        "sync reply s1": (SyncReply, IN, (), False),
        "sync reply s2": (LateReply, RESYNC, (R, S), True),  # no such sync was sent
        "foreign": (LateReply, RESYNC, (R, S), True),
        "garbled": (Garbled, RESYNC, (R, S), True),
        "timeout": (None, OUT, (R, S), False),
        "reset": (None, IN, (), False),
    },
    "resyncing after an older sync": {
        "send request": MISUSE,
        "send sync": (None, RESYNC, (R, S, S, S), True),
        "answer": (LateReply, RESYNC, (S, S), True),
        "sync reply, anonymous": (SyncReply, IN, (S,), False),  # the older one's, at least
        "sync reply s1": (SyncReply, IN, (S,), False),
        "sync reply s2": (SyncReply, IN, (), False),
        "foreign": (LateReply, RESYNC, (R, S, S), True),
        "garbled": (Garbled, RESYNC, (R, S, S), True),
        "timeout": (None, OUT, (R, S, S), False),
        "reset": (None, IN, (), False),
    },
    "resyncing, the late reply in": {
        "send sync": (None, RESYNC, (S, S), True),
        "answer": (LateReply, RESYNC, (S,), True),
        "sync reply, anonymous": (SyncReply, IN, (), False),
        "garbled": (Garbled, RESYNC, (S,), True),
        "timeout": (None, IN, (S,), False),  # nothing late can come: in step without it
    },
    "resyncing behind a stale sync": {
        "sync reply, anonymous": (SyncReply, RESYNC, (R, S), True),  # s2's: the request's due
        "sync reply s2": (SyncReply, RESYNC, (R, S), True),
        "answer": (LateReply, RESYNC, (S,), True),
        "send sync": (None, RESYNC, (S, R, S, S), True),
        "timeout": (None, OUT, (S, R, S), False),
    },
}


def apply(machine, action, argument):
    if action == "receive":
        kind, sync_id = argument if isinstance(argument, tuple) else (argument, None)
        return machine.receive(kind, "unit", sync_id)
    if action == "send_request":
        return machine.send_request(bool(argument))
    if action == "send_sync":
        return machine.send_sync(argument)
    return getattr(machine, action)()


def setup(name):
    machine = ReplySync()
    for action, argument in SETUPS[name]:
        apply(machine, action, argument)
    return machine


CASES = [(s, i, expected) for s, row in TABLE.items() for i, expected in row.items()]


@pytest.mark.parametrize(("situation", "what", "expected"), CASES,
                         ids=[f"{s}: {i}" for s, i, _ in CASES])
def test_every_state_and_input(situation, what, expected):
    machine = setup(situation)
    if expected == MISUSE:
        before = (machine.state, machine.unanswered, machine.awaiting)
        with pytest.raises(SyncMisuse):
            apply(machine, *INPUTS[what])
        assert (machine.state, machine.unanswered, machine.awaiting) == before
        return
    event_type, state, unanswered, awaiting = expected
    event = apply(machine, *INPUTS[what])
    assert type(event) is event_type if event_type else event is None
    assert (machine.state, machine.unanswered, machine.awaiting) == (state, unanswered, awaiting)


def test_the_table_covers_every_input_of_every_state():
    rows = {(s, i) for s, row in TABLE.items() for i in row}
    assert {(s, i) for s in ("idle", "awaiting", "out of step", "resyncing")
            for i in INPUTS} <= rows
    reached = {setup(s).state for s in SETUPS}
    assert reached == set(State)
    moves = {what for _, what in TRANSITIONS}
    assert moves == set(Input)


# -- random interleavings against a simulated in-order device ----------------------------
@dataclass(eq=False)
class Sent:
    """One thing the shell sent, as the device sees it."""

    is_sync: bool
    sync_shaped: bool
    sync_id: object
    function: int


class Line:
    """An in-order device: each reply is lost, garbled or queued; a read may time out while
    replies are still queued (they are late); a TCP line drops its queue on reconnection."""

    def __init__(self, data, mode):
        self.data, self.mode, self.queue, self.faulty = data, mode, deque(), True
        self.machine, self.awaited, self.tokens = ReplySync(), None, 0

    def send(self, item: Sent) -> None:
        fate = self.data.draw(st.sampled_from(["on time", "lost", "garbled"])) \
            if self.faulty else "on time"
        if fate != "lost":
            self.queue.append((item, fate == "garbled"))

    def read(self):
        """The next event, or None for a timeout (the machine told)."""
        late = self.faulty and self.data.draw(st.integers(0, 4)) == 0
        if not self.queue or late:
            self.machine.timeout()
            return None
        item, garbled = self.queue.popleft()
        return self.machine.receive(*self.sort(item, garbled))

    def sort(self, item, garbled):
        if garbled:
            return UnitKind.GARBLED, item, None
        if item.is_sync or item.sync_shaped:
            return UnitKind.SYNC, item, item.sync_id if self.mode == "rtu" else None
        awaited = self.awaited
        if self.mode == "tcp" and item is not awaited:
            return UnitKind.FOREIGN, item, None  # another transaction id
        if self.mode == "rtu" and awaited is not None and item.function != awaited.function:
            return UnitKind.FOREIGN, item, None
        return UnitKind.ANSWER, item, None

    def resync(self) -> bool:
        """The serial and RTU shells' resync: sync queries until in step or a timeout."""
        while self.machine.awaiting or self.machine.state is OUT:
            self.tokens += 1
            sync_id = self.tokens if self.mode == "rtu" else None
            self.machine.send_sync(sync_id)
            self.send(Sent(True, True, sync_id, 8))
            while True:
                event = self.read()
                if event is None:
                    return self.machine.state is IN
                if type(event) is SyncReply:
                    break
        assert self.machine.state is IN  # a sync reply ended the resync: back in step
        return True

    def exchange(self, sync_shaped: bool, function: int) -> bool:
        """One request and its reply; True when the machine took a reply for it."""
        if self.machine.state is OUT and not self.resync():
            return False
        request = self.awaited = Sent(False, sync_shaped, None, function)
        self.machine.send_request(sync_shaped)
        self.send(request)
        while self.machine.awaiting:
            event = self.read()
            if event is None or type(event) is Garbled:
                if self.mode == "tcp":  # the link closes the connection and starts afresh
                    self.machine.reset()
                    self.queue.clear()
                return False
            if type(event) is Reply:
                assert event.unit is request, "a reply taken for the wrong request"
                return True
        raise AssertionError("the wait ended without a reply, garble or timeout")

    def check_in_step(self) -> None:
        if self.machine.state is IN and not self.machine.awaiting:
            late = [item for item, _ in self.queue if not item.is_sync]
            assert not late, "in step while an earlier request's reply can still arrive"


@settings(max_examples=200, deadline=None)
@given(st.data(), st.sampled_from(["serial", "rtu", "tcp"]))
def test_random_interleavings_never_misattribute_and_recover(data, mode):
    line = Line(data, mode)
    for _ in range(data.draw(st.integers(1, 14))):
        sync_shaped = mode == "serial" and data.draw(st.integers(0, 6)) == 0
        line.exchange(sync_shaped, data.draw(st.sampled_from([3, 16])))
        line.check_in_step()
    line.faulty = False  # the line works again; each garbled leftover may spoil one exchange,
    for _ in range(sum(garbled for _, garbled in line.queue)):  # then every one succeeds
        if line.exchange(False, 3):
            break
    for _ in range(3):
        assert line.exchange(False, data.draw(st.sampled_from([3, 16])))
        assert line.machine.state is IN
        line.check_in_step()
