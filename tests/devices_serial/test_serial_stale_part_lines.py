"""A line that has begun to arrive when SerialLineTransport writes a request is stale, over a
real pty (as a serial port and as a VISA ASRL resource): the transport keeps its head until
the rest comes and then drops it whole (an unsolicited one set aside and counted), so its tail
never passes for the reply; whole lines already there are dropped (unsolicited ones counted).

The test writes the device's bytes itself: a line's head before the request, so that it is on
the line when the transport writes, and its tail with the reply once the request is heard."""

from __future__ import annotations

import fcntl
import os
import sys
import termios
import threading

import pytest
from waiting import wait_until

from drivers.base import DeviceTimeout
from drivers.serial_transport import SerialLineTransport, SyncQuery

SYNC = SyncQuery("SYNC", lambda line: line == "S")
ALERT_HEAD, ALERT_TAIL = b"!01 1 ID", b"LE --\r\n"  # `!01 1 IDLE --` cut as a port may cut it


def is_note(line: str) -> bool:
    """The peer's unprompted lines start with `!` (Zaber's alerts do)."""
    return line.startswith("!")


class PtyPeer:
    """The device's end of a real pty, written by the test: `send` puts bytes on the line (and
    waits until they are in the port's input queue); `script` says what to write back to each
    request (its bytes, or nothing), once the request has been read; `heard` keeps them."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        self.path = os.ttyname(self.slave)
        self.script: dict[bytes, bytes] = {}
        self.heard: list[bytes] = []
        self._serving = threading.Thread(target=self._serve, name="pty-peer", daemon=True)
        self._serving.start()

    def send(self, data: bytes) -> None:
        os.write(self.master, data)
        wait_until(lambda: self._unread() >= len(data), what="the bytes in the input queue")

    def _unread(self) -> int:
        queued = fcntl.ioctl(self.slave, termios.TIOCINQ, b"\0\0\0\0")
        return int.from_bytes(queued, sys.byteorder)

    def _serve(self) -> None:
        pending = b""
        while True:
            try:
                pending += os.read(self.master, 1024)
            except OSError:  # every end of the port closed: the test is over
                return
            while b"\r" in pending:
                request, pending = pending.split(b"\r", 1)
                self.heard.append(request)
                if reply := self.script.get(request):
                    os.write(self.master, reply)

    def close(self) -> None:
        os.close(self.slave)
        self._serving.join(timeout=5.0)
        os.close(self.master)


@pytest.fixture(params=["port", "asrl"])
def line_to(request):
    """line_to(sync, timeout_s, retries) -> (peer, transport): the transport on the pty as a
    serial port, or as a VISA ASRL resource."""
    opened = []

    def start(sync=SYNC, timeout_s=5.0, retries=2):
        peer = PtyPeer()
        opened.append(peer)
        where = ({"port": peer.path} if request.param == "port"
                 else {"resource": f"ASRL{peer.path}::INSTR"})
        transport = SerialLineTransport(**where, name="peer", timeout_s=timeout_s,
                                        retries=retries, sync=sync, is_unsolicited=is_note)
        opened.append(transport)
        return peer, transport

    yield start
    for thing in reversed(opened):
        thing.close()


def test_an_alert_begun_before_a_query_is_set_aside_whole(line_to):
    peer, line = line_to()
    peer.script = {b"Q1": ALERT_TAIL + b"A1\r\n"}
    peer.send(ALERT_HEAD)
    assert line.query("Q1", str) == "A1"
    assert peer.heard == [b"Q1"]  # no retry
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 1} and line.in_step


def test_an_alert_begun_before_a_command_sent_once_is_set_aside_whole(line_to):
    peer, line = line_to(retries=0)
    peer.script = {b"C1": ALERT_TAIL + b"OK\r\n", b"Q2": b"A2\r\n"}
    peer.send(ALERT_HEAD)
    assert line.exchange("C1") == "OK"
    assert line.query("Q2", str) == "A2"  # the next reply is its own: nothing left behind
    assert peer.heard == [b"C1", b"Q2"]
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 1} and line.in_step


def test_an_alert_head_after_a_reply_joins_its_tail_after_the_next_request(line_to):
    """The head comes with a reply (read past it), the tail with the next reply."""
    peer, line = line_to()
    peer.script = {b"Q1": b"A1\r\n" + ALERT_HEAD, b"Q2": ALERT_TAIL + b"A2\r\n"}
    assert line.query("Q1", str) == "A1"
    assert line.query("Q2", str) == "A2"
    assert peer.heard == [b"Q1", b"Q2"]
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 1} and line.in_step


def test_a_late_reply_begun_before_the_next_query_is_not_its_answer(line_to):
    """With no sync query nothing but the stale input tells a late reply: Q1's answer `1.25`
    comes after its timeout, cut by the next write, and its tail `25` (a number as good as
    any) is no answer to Q2."""
    peer, line = line_to(sync=None, timeout_s=0.2, retries=0)
    with pytest.raises(DeviceTimeout, match="'Q1'"):
        line.query("Q1", float)
    line.timeout_s = 5.0  # only the request the peer leaves unanswered is to time out
    peer.script = {b"Q2": b"25\r\n0.5\r\n"}
    peer.send(b"1.")
    assert line.query("Q2", float) == 0.5
    assert peer.heard == [b"Q1", b"Q2"]
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 0}


def test_whole_lines_there_before_a_request_are_dropped_the_unsolicited_counted(line_to):
    peer, line = line_to()
    peer.script = {b"Q1": b"A1\r\n"}
    peer.send(b"!a\r\nLATE\r\n!b\r\n")
    assert line.query("Q1", str) == "A1"
    assert peer.heard == [b"Q1"]
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 2} and line.in_step


def test_a_stale_part_line_that_never_ends_costs_the_reply_it_runs_into(line_to):
    """Noise with no terminator before a query: the line it begins takes in the reply, so the
    reply is dropped with it (a timeout, then a resync and a retry that are answered), never
    read as a garbled or wrong reply."""
    peer, line = line_to(timeout_s=0.2, retries=1)
    peer.script = {b"Q1": b"A1\r\n", b"SYNC": b"S\r\n"}
    peer.send(b"\x00\xfe")
    assert line.query("Q1", str) == "A1"
    assert peer.heard == [b"Q1", b"SYNC", b"Q1"]
    assert line.line_counts() == {"resyncs": 1, "unsolicited": 0} and line.in_step
