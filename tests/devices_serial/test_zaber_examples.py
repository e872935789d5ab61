"""Zaber's own published exchanges, sent byte for byte to the emulator over a real pty.

Sources (Zaber's firmware-7 protocol manual pages themselves could not be reached offline):
Zaber's article "Zaber's ASCII Protocol" (firmware team, 2022) for the system reset exchange,
the reply fields and "alerts are disabled by default"; Zaber's ASCII protocol wiki for line
endings (CR, LF or both in; CR LF out; no echo); the checksummed replies in zaber.serial's and
Zaber's MATLAB toolbox's tests; the toolbox's device-scope `get pos` of a two-axis device and
its integrated rotary stage rejecting `get peripheralid`."""

import math

import pytest
import serial

from sim.devices.motion import VirtualClock
from sim.devices.zaber import ZaberEmulator, lrc


@pytest.fixture
def session(opened):
    """A pyserial session with device 1 (two axes) on an instant clock."""
    emu = ZaberEmulator(VirtualClock(math.inf), {1: {}, 2: {}})
    emu.start()
    opened.append(emu)
    with serial.Serial(emu.endpoint, 115200, timeout=1.0) as port:
        port.emulator = emu
        yield port


def exchange(port: serial.Serial, sent: bytes) -> bytes:
    """Send bytes as they are and read back one line with its terminator."""
    port.write(sent)
    return port.read_until(b"\r\n")


def test_article_system_reset_and_reply_fields(session):
    assert exchange(session, b"/1 system reset\n") == b"@01 0 OK IDLE -- 0\r\n"
    # after the reset the stepper axes have no reference position until homed
    assert exchange(session, b"/1 1 get pos\n") == b"@01 1 OK IDLE WR 0\r\n"


def test_article_alerts_are_disabled_by_default(session):
    assert exchange(session, b"/1 get comm.alert\n") == b"@01 0 OK IDLE -- 0\r\n"


@pytest.mark.parametrize("end", [b"\r", b"\n", b"\r\n"])
def test_wiki_any_line_ending_in_crlf_out_and_no_echo(session, end):
    assert exchange(session, b"/1 1 get resolution" + end) == b"@01 1 OK IDLE -- 64\r\n"
    assert session.in_waiting == 0


def test_library_checksummed_replies(session):
    assert exchange(session, b"/1 set comm.checksum 1\n") == b"@01 0 OK IDLE -- 0:8D\r\n"
    assert lrc("1 3 9 OK IDLE -- 0") == "61"  # the toolbox's `@1 3 9 OK IDLE -- 0:61`


def test_toolbox_device_scope_get_answers_for_each_axis(session):
    assert exchange(session, b"/1 1 set pos 12345\n") == b"@01 1 OK IDLE -- 0\r\n"
    assert exchange(session, b"/1 2 set pos 23456\n") == b"@01 2 OK IDLE -- 0\r\n"
    assert exchange(session, b"/1 0 get pos\r\n") == b"@01 0 OK IDLE -- 12345 23456\r\n"


def test_toolbox_integrated_stage_has_no_peripheral(session):
    assert exchange(session, b"/1 1 get peripheralid\n") == b"@01 1 RJ IDLE -- BADCOMMAND\r\n"
    assert exchange(session, b"/1 1 get peripheral.serial\n") == \
        b"@01 1 RJ IDLE -- BADCOMMAND\r\n"
