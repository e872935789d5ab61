"""SerialLineTransport with lines the driver declares unsolicited (`is_unsolicited`), against a
scripted line device on a real pty: such a line, before, between or after reply lines and
whatever its bytes, is set aside and counted, never taken for a reply, and costs no retry and
no resync; the line's other rules (late replies, garbled replies, timeouts) stay as they are."""

import pytest
from waiting import HANG_S

from drivers.base import DeviceTimeout, ProtocolError
from drivers.serial_transport import SerialLineTransport, SyncQuery
from sim.devices.pty_server import PtyServer

SYNC = SyncQuery("SYNC", lambda line: line == "S")


def is_note(line: str) -> bool:
    """The scripted device's unprompted lines start with `!`."""
    return line.startswith("!")


class ScriptedDevice:
    """A line device answering each request with its script's bytes (nothing for a request
    the script leaves out), and keeping the requests it heard."""

    def __init__(self, script: dict[bytes, bytes]):
        self.script, self.heard = script, []

    def __call__(self, line: bytes) -> bytes | None:
        self.heard.append(line)
        return self.script.get(line)


@pytest.fixture
def line_to():
    """line_to(script, timeout_s, retries) -> (device, transport) on a pty of its own."""
    opened = []

    def start(script, timeout_s=HANG_S, retries=2):
        device = ScriptedDevice(script)
        server = PtyServer(device, terminators=b"\r", name="scripted")
        opened.append(server)
        transport = SerialLineTransport(server.start(), name="scripted", timeout_s=timeout_s,
                                        retries=retries, sync=SYNC, is_unsolicited=is_note)
        opened.append(transport)
        return device, transport

    yield start
    for thing in reversed(opened):
        (thing.close if isinstance(thing, SerialLineTransport) else thing.stop)()


def test_a_line_before_the_reply_is_set_aside_and_counted(line_to):
    device, line = line_to({b"Q1": b"!a\r\nA1\r\n", b"Q2": b"!b\r\n!c\r\nA2\r\n"})
    assert line.query("Q1", str) == "A1"
    assert line.query("Q2", str) == "A2"
    assert device.heard == [b"Q1", b"Q2"]  # nothing asked twice
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 3} and line.in_step


def test_before_between_and_after_the_replies_a_resync_reads(line_to):
    """Q1's reply comes late, with the sync query's: an unprompted line ahead of it, one
    between it and the sync reply, one after the sync reply (ahead of Q2's own reply). Only
    the timeout costs a resync."""
    device, line = line_to({b"SYNC": b"!before\r\nA1\r\n!between\r\nS\r\n",
                            b"Q2": b"!after\r\nA2\r\n"}, timeout_s=0.2, retries=0)
    with pytest.raises(DeviceTimeout):
        line.query("Q1", str)
    assert not line.in_step
    line.timeout_s = HANG_S  # only the request the device leaves unanswered is to time out
    assert line.query("Q2", str) == "A2"
    assert device.heard == [b"Q1", b"SYNC", b"Q2"]
    assert line.line_counts() == {"resyncs": 1, "unsolicited": 3} and line.in_step


def test_an_unprompted_line_with_bytes_no_reply_has_is_set_aside_not_garbled(line_to):
    device, line = line_to({b"Q1": b"!\x80\x01:ZZ\r\nA1\r\n", b"Q2": b"\x80\r\nA2\r\n"},
                           retries=0)
    assert line.exchange("Q1") == "A1"
    assert line.unsolicited == 1
    with pytest.raises(ProtocolError, match="garbled reply to 'Q2'"):
        line.exchange("Q2")  # a garbled line of no declared kind is still the reply, garbled
    assert line.line_counts() == {"resyncs": 0, "unsolicited": 1} and line.in_step


def test_unprompted_lines_alone_are_no_reply(line_to):
    """A request answered only by unprompted lines times out (its reply may still come)."""
    device, line = line_to({b"Q1": b"!a\r\n!b\r\n", b"SYNC": b"S\r\n", b"Q2": b"A2\r\n"},
                           timeout_s=0.2, retries=0)
    with pytest.raises(DeviceTimeout, match="'Q1'"):
        line.exchange("Q1")
    assert line.unsolicited == 2 and not line.in_step
    line.timeout_s = HANG_S  # only the request the device leaves unanswered is to time out
    assert line.exchange("Q2") == "A2"
    assert device.heard == [b"Q1", b"SYNC", b"Q2"]
    assert line.line_counts() == {"resyncs": 1, "unsolicited": 2}
