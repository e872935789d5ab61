"""RTU framing over real ptys: the driver's client takes a reply as its bytes arrive (ended by
its length) and bounds a short reply by reply_s; the emulator ends a frame at t3.5 of its
configured baud rate (leftovers of a truncated frame dropped only after that much silence);
a pulled-cable fault cuts the line only after the host has read the last reply."""

import math
import os
import threading
import time
import tty

import pytest
import serial
from modbus_testkit import STAGE_MAP, crc16  # noqa: I001 - the test folder's own helpers
from waiting import wait_until

from drivers.base import DeviceTimeout
from drivers.modbus_rtu_client import RtuClient
from drivers.modbus_transport import ModbusLink, ModbusTimeouts
from sim.devices.faults import FaultSpec
from sim.devices.modbus_server import ModbusEmulatorServer, rtu_silent_interval_s
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock


def frame(body: bytes) -> bytes:
    return body + crc16(body)


READ_8_9 = frame(bytes([1, 3, 0, 8, 0, 2]))  # read holding registers 8..9 of unit 1
REPLY = frame(bytes([1, 3, 4, 0x12, 0x34, 0x56, 0x78]))  # ... answered with 0x1234, 0x5678


class ScriptedDevice:
    """A device on a real pty that answers each 8-byte request with REPLY, cut into the
    given pieces with a pause before each piece after the first."""

    def __init__(self, pieces: list[int], pause_s: float):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.pieces, self.pause_s = pieces, pause_s
        self.sent = 0  # pieces written so far (counted as each write begins)
        self.closing = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        request = b""
        while len(request) < len(READ_8_9):
            request += os.read(self.master, 64)
        start = 0
        for i, size in enumerate(self.pieces):
            if i and self.closing.wait(self.pause_s):
                return
            self.sent += 1  # before the write: a reader done with the reply sees it counted
            os.write(self.master, REPLY[start:start + size])
            start += size

    def close(self) -> None:
        self.closing.set()
        self.thread.join(5.0)
        os.close(self.master)
        os.close(self.slave)


def test_the_driver_client_assembles_a_reply_that_comes_in_pieces():
    device = ScriptedDevice([2, 3, 4], pause_s=0.03)
    client = RtuClient(device.path, baudrate=115200, timeout=1.0, retries=0)
    try:
        assert client.connect()
        reply = client.read_holding_registers(8, count=2, device_id=1)
        assert device.sent == 3  # it waited for the last piece
        assert reply.registers == [0x1234, 0x5678]
    finally:
        client.close()
        device.close()


def test_a_request_that_all_went_out_is_sent_however_long_the_writer_was_held_off():
    # pyserial's write checks its write timeout after a write that took every byte, so a
    # writer descheduled longer than the timeout (a loaded machine) fails a request that went
    # out. A write timeout that has always expired stands for that stall here.
    master, slave = os.openpty()
    bare = serial.Serial(os.ttyname(slave), write_timeout=1e-9)
    try:
        with pytest.raises(serial.SerialTimeoutException):
            bare.write(READ_8_9)
        assert os.read(master, 64) == READ_8_9  # ... though every byte went out
    finally:
        bare.close()
        os.close(master)
        os.close(slave)
    device = ScriptedDevice([len(REPLY)], pause_s=0.0)
    client = RtuClient(device.path, baudrate=115200, timeout=1.0, retries=0)
    try:
        assert client.connect()
        client.socket.write_timeout = 1e-9
        reply = client.read_holding_registers(8, count=2, device_id=1)
        assert reply.registers == [0x1234, 0x5678]
    finally:
        client.close()
        device.close()


def test_a_reply_that_stays_short_times_out_at_reply_s_in_all():
    # a byte every 0.25 s: the wait after each byte gets only what is left of reply_s (0.3 s),
    # so the timeout comes at 0.3 s, with the reply short; a wait that started afresh with
    # each byte would take the whole reply, a byte at a time
    device = ScriptedDevice([1] * len(REPLY), pause_s=0.25)
    link = ModbusLink("rtu", device.path, timeouts=ModbusTimeouts(reply_s=0.3), read_retries=0)
    try:
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match="dev: timeout after 0.3 s"):
            link.read("dev", "holding", 8, 2, 1)
        assert time.monotonic() - t0 >= 0.3
        assert device.sent < len(REPLY)
    finally:
        link.close()
        device.close()


def test_the_silent_interval_is_t35_of_the_configured_baud_rate():
    for baud in (300, 1200, 9600, 19200):  # 3.5 characters of 1 start, 8 data, 2 more bits
        assert rtu_silent_interval_s(baud) == pytest.approx(3.5 * (1 + 8 + 2) / baud)
    for baud in (38400, 115200, 921600):  # the spec's fixed value above 19200 baud
        assert rtu_silent_interval_s(baud) == pytest.approx(1.75e-3)


@pytest.fixture
def stage_server():
    """start(baudrate, faults) -> a running RTU emulator with one stage (unit 1) at 12.345
    deg (actual_position 12345 = registers 0, 12345); stopped after the test."""
    made = []

    def start(baudrate=115200, faults=None):
        emu = ModbusStageEmulator(VirtualClock(math.inf), STAGE_MAP, (-95.0, 95.0), 20.0, 80.0,
                                  position_deg=12.345)
        server = ModbusEmulatorServer("rtu", {1: emu}, faults=faults, baudrate=baudrate)
        server.start()
        made.append(server)
        return server

    yield start
    for server in made:
        server.stop()


def exchange(path: str, pieces: list[bytes], pause_s: float) -> bytes:
    """Write the pieces with pauses between them; all that comes back within 0.3 s."""
    with serial.Serial(path, 115200, timeout=0.3) as port:
        for i, piece in enumerate(pieces):
            if i:
                time.sleep(pause_s)
            port.write(piece)
        return port.read(64)


STAGE_REPLY = frame(bytes([1, 3, 4, 0, 0, 0x30, 0x39]))  # 12345 mdeg, high word first


@pytest.mark.parametrize(("baud", "pause_s", "answered"), [
    (115200, 0.05, True),   # 50 ms >> t3.5 (1.75 ms): the truncated frame is dropped
    (300, 0.005, False),    # 5 ms << t3.5 (128 ms): leftover and request are one bad frame
])
def test_a_truncated_frame_is_dropped_only_after_t35_of_silence(stage_server, baud, pause_s,
                                                                  answered):
    server = stage_server(baudrate=baud)
    reply = exchange(server.endpoint, [READ_8_9[:5], READ_8_9], pause_s)
    assert reply == (STAGE_REPLY if answered else b"")


def test_a_frame_with_a_pause_shorter_than_t35_is_one_frame(stage_server):
    server = stage_server(baudrate=300)  # t3.5 = 128 ms
    assert exchange(server.endpoint, [READ_8_9[:3], READ_8_9[3:]], 0.005) == STAGE_REPLY


def test_a_pulled_cable_waits_until_a_slow_host_has_read_the_reply(stage_server):
    server = stage_server(faults=FaultSpec(disconnect_after=1))
    with serial.Serial(server.endpoint, 115200, timeout=0.5) as port:
        port.write(READ_8_9)
        # the host reads late: after the reply is queued for it and the cut is due
        wait_until(lambda: port.in_waiting >= len(STAGE_REPLY) and server.disconnected,
                   what="the reply queued and the cut due")
        assert port.read(len(STAGE_REPLY)) == STAGE_REPLY
        wait_until(lambda: not os.path.exists(server.endpoint), what="the line gone")
        with pytest.raises(serial.SerialException):
            port.write(READ_8_9)
            port.read(len(STAGE_REPLY))
