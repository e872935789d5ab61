"""Zaber alerts over a real pty: the emulator sends `!dd a IDLE flag` when a motion ends (while
comm.alert is 1), and gonio's driver, which leaves comm.alert as the device has it, never takes
an alert that arrives where a reply was due for that reply: its transport sets every alert
aside (a wrong checksum or not, whole or cut by the driver's next request), with no retry and
no resync."""

import math

import pytest
import serial
from waiting import HANG_S

from drivers.zaber import ZaberController
from sim.devices.motion import VirtualClock
from sim.devices.zaber import ZaberEmulator, lrc

UNIT = 0.015 / 64  # X-RSW60A microstep at the default resolution, degrees


@pytest.fixture
def serve(opened):
    """serve(clock, axes, alerts) -> a started emulator (stopped after the test)."""

    def start(clock, axes, alerts=True):
        emu = ZaberEmulator(clock, axes, alerts=alerts)
        emu.start()
        opened.append(emu)
        return emu

    return start


def lines(session: serial.Serial, command: str | None = None, count: int = 1) -> list[str]:
    """Send a command (if any), then read `count` lines (each ended by CR LF)."""
    if command is not None:
        session.write(command.encode("ascii") + b"\r\n")
    read = [session.read_until(b"\r\n").decode("ascii") for _ in range(count)]
    assert all(line.endswith("\r\n") for line in read), f"lines cut short: {read!r}"
    return [line.removesuffix("\r\n") for line in read]


def test_an_alert_goes_out_when_the_motion_ends_with_no_command_asking(serve):
    emu = serve(VirtualClock(50.0), {1: {}})
    with serial.Serial(emu.endpoint, 115200, timeout=HANG_S) as session:
        assert lines(session, "/1 1 move abs 64000") == ["@01 1 OK BUSY -- 0"]  # 15 deg
        assert lines(session) == ["!01 1 IDLE --"]  # nothing was sent: the device spoke
        assert not emu.axes[1].busy() and emu.axis_position_deg(1) == pytest.approx(15.0)
        assert lines(session, "/1 1 get pos") == ["@01 1 OK IDLE -- 64000"]  # once a motion


def test_an_alert_goes_out_unasked_over_tcp_too():
    # served over TCP (a TCPIP SOCKET resource under --sim), the alert watcher runs as on a pty
    emu = ZaberEmulator(VirtualClock(50.0), {1: {}}, alerts=True)
    try:
        endpoint = emu.start_tcp()
        with serial.serial_for_url(f"socket://{endpoint}", timeout=HANG_S) as session:
            assert lines(session, "/1 1 move abs 64000") == ["@01 1 OK BUSY -- 0"]
            assert lines(session) == ["!01 1 IDLE --"]  # nothing was sent: the device spoke
    finally:
        emu.stop()


def checked(kind: str, body: str) -> str:
    """A message as a device sends it while comm.checksum is 1."""
    return f"{kind}{body}:{lrc(body)}"


def test_a_move_that_ends_at_once_alerts_after_its_reply_for_each_axis(serve):
    emu = serve(VirtualClock(math.inf), {1: {}, 2: {"homed": False}})
    with serial.Serial(emu.endpoint, 115200, timeout=HANG_S) as session:
        assert lines(session, "/1 set comm.checksum 1") == [checked("@", "01 0 OK IDLE WR 0")]
        assert lines(session, "/1 0 move abs 1000", 3) == [
            checked("@", "01 0 OK IDLE WR 0"), checked("!", "01 1 IDLE --"),
            checked("!", "01 2 IDLE WR")]  # axis 2 has no reference yet
        assert lines(session, "/1 set comm.alert 0") == [checked("@", "01 0 OK IDLE WR 0")]
        assert lines(session, "/1 1 move abs 0") == [checked("@", "01 1 OK IDLE -- 0")]
        assert lines(session, "/1 1 get pos") == [checked("@", "01 1 OK IDLE -- 0")]


def test_every_device_on_the_chain_alerts_whoever_the_command_addresses(serve):
    clock = VirtualClock(0.0)  # frozen: motions end when the test moves time on
    emu = serve(clock, {(1, 1): {}, (2, 1): {}})
    with serial.Serial(emu.endpoint, 115200, timeout=HANG_S) as session:
        assert lines(session, "/2 1 move rel 500") == ["@02 1 OK BUSY -- 0"]
        assert lines(session, "/1 1 stop") == ["@01 1 OK IDLE -- 0"]  # device 2 still moving
        clock.advance(60.0)
        assert lines(session, "/1 1 get pos", 2) == ["!02 1 IDLE --", "@01 1 OK IDLE -- 0"]


def test_the_driver_sets_aside_an_alert_that_comes_before_its_reply(serve):
    """A motion begun before the driver opened the device ends during the opening: its alert
    comes before the reply to the driver's first command, which is not taken for it."""
    clock = VirtualClock(0.0)
    emu = serve(clock, {1: {}})
    with serial.Serial(emu.endpoint, 115200, timeout=HANG_S) as session:
        assert lines(session, "/1 1 move abs 4000") == ["@01 1 OK BUSY -- 0"]
    clock.advance(60.0)
    with ZaberController(emu.endpoint, timeout_s=1.0, retries=2) as ctl:
        assert ctl.transport.unsolicited == 1 and ctl.transport.resyncs == 0
        assert emu.devices[1].settings["comm.alert"] == 1  # the device's saved setting stays
        assert emu.devices[1].settings["comm.checksum"] == 1
        assert ctl.identity() == {"device_id": "50001", "serial": "120001",
                                  "firmware": "7.38", "address": "1"}
        assert ctl.axis(1).position() == pytest.approx(4000 * UNIT)


def test_the_driver_reads_through_alerts_of_a_device_it_does_not_use(serve):
    clock = VirtualClock(0.0)
    emu = serve(clock, {(1, 1): {}, (2, 1): {}})
    with serial.Serial(emu.endpoint, 115200, timeout=HANG_S) as session:
        assert lines(session, "/2 1 move rel 500") == ["@02 1 OK BUSY -- 0"]
        # the lab saved device 1 with alerts off: only device 2 alerts
        assert lines(session, "/1 set comm.alert 0") == ["@01 0 OK IDLE -- 0"]
    with ZaberController(emu.endpoint, timeout_s=1.0, retries=2, address=1) as ctl:
        axis = ctl.axis(1)
        axis.move_to(2.0)
        clock.advance(60.0)  # both motions end: device 2's alert comes before the next reply
        assert axis.position() == pytest.approx(2.0, abs=UNIT)
        assert ctl.transport.unsolicited == 1 and ctl.transport.resyncs == 0
        assert emu.devices[2].settings["comm.alert"] == 1  # a device the driver left alone
        assert axis.wait(timeout_s=HANG_S) == pytest.approx(2.0, abs=UNIT)


def test_moves_and_waits_with_alerts_on_take_no_alert_for_a_reply(serve):
    """Each motion's end is heard as an alert before the next reply (one per axis that moved):
    every wait returns the target at its first poll, each alert set aside, none retried."""
    clock = VirtualClock(0.0)
    emu = serve(clock, {1: {}, 2: {}})
    with ZaberController(emu.endpoint, timeout_s=1.0, retries=0) as ctl:
        sample, arm = ctl.axis(1), ctl.axis(2)
        requests = emu.server.requests
        for n, target in enumerate((5.0, -12.5, 30.0), start=1):
            sample.move_to(target)
            clock.advance(60.0)
            assert sample.wait(timeout_s=HANG_S) == pytest.approx(target, abs=UNIT)
            assert ctl.transport.unsolicited == n
        sample.move_to(0.0)
        arm.move_to(45.0)
        clock.advance(60.0)  # both end: two alerts before the next reply
        assert arm.wait(timeout_s=HANG_S) == pytest.approx(45.0, abs=UNIT)
        assert sample.position() == 0.0
        assert ctl.transport.line_counts() == {"resyncs": 0, "unsolicited": 5}
        assert sample.line_counts() == arm.line_counts() == ctl.transport.line_counts()
        # a move and one poll each: no query asked twice, no sync query
        assert emu.server.requests - requests == 3 * 2 + 2 + 2
    assert emu.devices[1].settings["comm.alert"] == 1


def wrong_checksums(handler, spoiled: list[bytes]):
    """The handler, its alerts' checksums made wrong (a device whose alert was hit by noise),
    each spoiled alert appended to `spoiled`."""
    def spoil(msg: bytes) -> bytes:
        if not msg.startswith(b"!"):
            return msg
        spoiled.append(msg[:-4] + b"00\r\n")
        return spoiled[-1]

    def handle(line: bytes) -> bytes | None:
        out = handler(line)
        return None if out is None else b"".join(map(spoil, out.splitlines(keepends=True)))
    return handle


def test_an_alert_with_a_wrong_checksum_is_set_aside_too(serve):
    clock = VirtualClock(0.0)
    emu = serve(clock, {1: {}})
    spoiled: list[bytes] = []
    emu.server.handler = wrong_checksums(emu.handle_line, spoiled)
    with ZaberController(emu.endpoint, timeout_s=1.0, retries=0) as ctl:
        axis = ctl.axis(1)
        axis.move_to(3.0)
        clock.advance(60.0)
        assert axis.wait(timeout_s=HANG_S) == pytest.approx(3.0, abs=UNIT)
        assert spoiled == [b"!01 1 IDLE --:00\r\n"] and lrc("01 1 IDLE --") != "00"
        assert ctl.transport.line_counts() == {"resyncs": 0, "unsolicited": 1}


def cut_after_reply(handler, cut: list[bytes]):
    """The handler, an alert that ends its output cut in two as a port may cut it: its first
    bytes go out with the reply, the rest just before the next reply (after the driver has
    written its next request); each cut alert appended to `cut`."""
    tail = b""

    def handle(line: bytes) -> bytes | None:
        nonlocal tail
        out = handler(line)
        if out is None:
            return None
        held, tail = tail, b""
        *replies, last = out.splitlines(keepends=True)
        if last.startswith(b"!"):
            cut.append(last)
            last, tail = last[:8], last[8:]
        return held + b"".join(replies) + last
    return handle


def test_an_alert_cut_by_the_next_request_is_set_aside_whole(serve):
    """A motion that ends as its move's reply goes out: the alert's head is on the line when
    the driver writes its next request, its tail comes after it, before that request's reply."""
    emu = serve(VirtualClock(math.inf), {1: {}})
    cut: list[bytes] = []
    emu.server.handler = cut_after_reply(emu.handle_line, cut)
    with ZaberController(emu.endpoint, timeout_s=1.0, retries=2) as ctl:
        axis = ctl.axis(1)
        requests = emu.server.requests
        axis.move_to(10.0)
        assert axis.position() == pytest.approx(10.0, abs=UNIT)
        assert cut == [checked("!", "01 1 IDLE --").encode("ascii") + b"\r\n"]
        assert emu.server.requests - requests == 2  # the move and one get pos: no retry
        assert ctl.transport.line_counts() == {"resyncs": 0, "unsolicited": 1}
        assert ctl.transport.in_step
