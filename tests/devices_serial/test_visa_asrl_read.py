"""An ASRL resource read honours its deadline: it returns what has arrived, as a serial port's
read does, instead of waiting (pyvisa-py: one byte at a time, each with the whole timeout) for
the rest of a line that may never come. A pty trickles a reply in pieces the test writes
between reads: each read returns the piece written, none is lost, and a read with nothing
coming returns nothing, the reply that comes after it whole."""

import os

import pytest
from waiting import HANG_S

from drivers.byte_link import LineSettings
from drivers.visa_link import READ_SLICE_S, VisaLink

REPLY = (b"1.2", b"34567E", b"-06;0,", b'"No error"\n')


@pytest.fixture
def trickled():
    """(the VISA link on a pty, the descriptor the test writes the device's bytes to)."""
    leader, follower = os.openpty()
    link = VisaLink(f"ASRL{os.ttyname(follower)}::INSTR", LineSettings(), b"\n", 1.0)
    yield link, leader
    link.close()
    os.close(leader)
    os.close(follower)


def test_each_read_returns_the_piece_that_came(trickled):
    link, device = trickled
    pieces = []
    for piece in REPLY:
        os.write(device, piece)
        pieces.append(link.read(HANG_S))  # the piece is there: no wait for the line's end
    assert pieces == list(REPLY)
    assert link.read(0.0) == b""


def test_a_read_with_nothing_coming_returns_nothing_then_the_reply_whole(trickled):
    link, device = trickled
    for wait_s in (0.0, READ_SLICE_S / 2, READ_SLICE_S):  # none, part of a slice, a slice
        assert link.read(wait_s) == b""
    link.write(b"READ?\n")
    assert os.read(device, 64) == b"READ?\n"
    os.write(device, b"2.000000E-06\n")
    assert link.read(HANG_S) == b"2.000000E-06\n"
