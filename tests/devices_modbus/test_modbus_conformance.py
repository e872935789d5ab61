"""The Modbus emulators answer as the spec and real devices do, over real sockets and ptys:
pipelined TCP requests in order (3, and 100 in one send, also in odd pieces), function 08
sub-function 0000 echoed and every other sub-function, like any function the units lack,
exception 01 with the function byte of the request | 0x80 (0xC1 for 0x41)."""

import socket
import struct
import time

import pytest
import serial
from modbus_testkit import DETECTOR_UNIT, STAGE_UNIT, crc16  # noqa: I001 - the folder's own helpers
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from waiting import HANG_S

from sim.devices.register_map import ILLEGAL_FUNCTION

ABSENT_UNIT = 9
GATEWAY_TARGET_FAILED = 11


def mbap(tid: int, unit: int, pdu: bytes) -> bytes:
    """A Modbus TCP request frame (written here, not imported)."""
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def tcp_replies(server, data: bytes, expected: int, chunk: int | None = None,
                timeout_s: float = 5.0) -> list[tuple[int, int, bytes]]:
    """Send data on one connection (in one sendall, or in pieces of `chunk` bytes) and read
    `expected` reply frames: [(transaction id, unit, PDU)] in arrival order."""
    host, port = server.endpoint.rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=timeout_s) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if chunk is None:
            sock.sendall(data)
        else:
            for at in range(0, len(data), chunk):
                sock.sendall(data[at:at + chunk])
                time.sleep(0.001)  # separate segments
        got, frames = b"", []
        while len(frames) < expected:
            more = sock.recv(65536)
            assert more, f"connection closed after {len(frames)} of {expected} replies"
            got += more
            while len(got) >= 7 and len(got) >= 6 + struct.unpack(">H", got[4:6])[0]:
                tid, protocol, length, unit = struct.unpack(">HHHB", got[:7])
                assert protocol == 0
                frames.append((tid, unit, got[7:6 + length]))
                got = got[6 + length:]
    return frames


def rtu_reply(port: serial.Serial, unit: int, pdu: bytes, silent: bool = False) -> bytes:
    """One RTU request on the pty; the reply's PDU (CRC checked), b"" for silence. The first
    byte of an expected reply is awaited for HANG_S (a hang guard: a loaded machine may be
    slow to answer); the frame ends when the line has been quiet for the port's timeout, which
    is also how long a `silent` unit is given to prove it stays silent."""
    frame = bytes([unit]) + pdu
    port.write(frame + crc16(frame))
    quiet_s = port.timeout
    port.timeout = quiet_s if silent else HANG_S
    try:
        reply = port.read(1)
    finally:
        port.timeout = quiet_s
    while reply and (chunk := port.read(256)):  # until the line has been quiet
        reply += chunk
    if not reply:
        return b""
    assert reply[0] == unit and crc16(reply[:-2]) == reply[-2:], reply.hex()
    return reply[1:-2]


READ_POSITION = struct.pack(">BHH", 3, 8, 2)  # holding 8..9 of the stage: actual_position
READ_DETECTOR = struct.pack(">BHH", 4, 0, 5)  # input 0..4 of the amplifier
SET_AVERAGING = struct.pack(">BHH", 6, 2, 4)  # holding 2 of the amplifier: averaging = 4
ECHO = bytes([8, 0, 0, 0xBE, 0xEF])
UNKNOWN = bytes([0x41, 0, 0])


@pytest.mark.parametrize("count, chunk", [(3, None), (100, None), (100, 7)],
                         ids=["3-one-send", "100-one-send", "100-in-7-byte-pieces"])
def test_pipelined_tcp_requests_are_answered_in_order(rig, count, chunk):
    r = rig("tcp")
    r.stage.move_to(12.5)
    cycle = [(STAGE_UNIT, READ_POSITION), (DETECTOR_UNIT, READ_DETECTOR),
             (DETECTOR_UNIT, SET_AVERAGING), (STAGE_UNIT, UNKNOWN), (DETECTOR_UNIT, ECHO)]
    sent = [cycle[i % len(cycle)] for i in range(count)]
    data = b"".join(mbap(1000 + i, unit, pdu) for i, (unit, pdu) in enumerate(sent))
    replies = tcp_replies(r.server, data, count, chunk)
    assert [(tid, unit) for tid, unit, _ in replies] == [
        (1000 + i, unit) for i, (unit, _) in enumerate(sent)]
    for (_, _, reply), (_, request) in zip(replies, sent, strict=True):
        if request == READ_POSITION:
            assert reply == bytes([3, 4]) + struct.pack(">i", 12500)
        elif request == READ_DETECTOR:
            assert reply[:2] == bytes([4, 10])
        elif request == UNKNOWN:
            assert reply == bytes([0xC1, ILLEGAL_FUNCTION])
        else:  # a write single register and the echo answer with the request itself
            assert reply == request
    assert r.detector.settings()["averaging"] == 4


def test_pipelined_replies_of_a_slow_unit_keep_their_order(rig):
    r = rig("tcp", stage_faults={"latency_s": 0.05})
    sent = [(STAGE_UNIT, READ_POSITION), (DETECTOR_UNIT, READ_DETECTOR),
            (STAGE_UNIT, READ_POSITION)]
    data = b"".join(mbap(i, unit, pdu) for i, (unit, pdu) in enumerate(sent))
    t0 = time.monotonic()
    replies = tcp_replies(r.server, data, len(sent))
    assert time.monotonic() - t0 >= 0.1  # two delayed replies, one after the other
    assert [(tid, unit) for tid, unit, _ in replies] == [(0, 1), (1, 2), (2, 1)]


# (request PDU, expected reply PDU): the echo works; reserved (0008, 0063) and implemented-
# by-pymodbus-for-the-whole-process sub-functions (0001 restart, 000A clear counters, 000B
# bus message count) and functions (07, 11h) are the unit's exception 01.
DIAGNOSTICS = [
    (ECHO, ECHO),
    (bytes([8, 0, 8, 0, 0]), bytes([0x88, ILLEGAL_FUNCTION])),
    (bytes([8, 0, 0x63, 0, 0]), bytes([0x88, ILLEGAL_FUNCTION])),
    (bytes([8, 0, 1, 0, 0]), bytes([0x88, ILLEGAL_FUNCTION])),
    (bytes([8, 0, 0x0A, 0, 0]), bytes([0x88, ILLEGAL_FUNCTION])),
    (bytes([8, 0, 0x0B, 0, 0]), bytes([0x88, ILLEGAL_FUNCTION])),
    (bytes([7]), bytes([0x87, ILLEGAL_FUNCTION])),
    (bytes([0x11]), bytes([0x91, ILLEGAL_FUNCTION])),
]


def test_tcp_diagnostics_and_unknown_functions_per_spec(rig):
    r = rig("tcp")
    cases = [*DIAGNOSTICS, (UNKNOWN, bytes([0xC1, ILLEGAL_FUNCTION])),
             (bytes([0x7F]), bytes([0xFF, ILLEGAL_FUNCTION]))]
    data = b"".join(mbap(i, STAGE_UNIT, pdu) for i, (pdu, _) in enumerate(cases))
    data += mbap(99, ABSENT_UNIT, UNKNOWN)
    replies = tcp_replies(r.server, data, len(cases) + 1)
    assert [reply for _, _, reply in replies] == [
        *(want for _, want in cases), bytes([0xC1, GATEWAY_TARGET_FAILED])]


def test_rtu_diagnostics_per_spec_and_the_resync_echo_still_works(rig):
    r = rig("rtu")
    with serial.Serial(r.server.endpoint, 115200, timeout=0.05) as port:
        assert [rtu_reply(port, STAGE_UNIT, pdu) for pdu, _ in DIAGNOSTICS] == [
            want for _, want in DIAGNOSTICS]
        assert rtu_reply(port, ABSENT_UNIT, bytes([7]), silent=True) == b""  # absent: silent
    assert r.stage.position() == 0.0


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_pymodbus_client_sees_the_echo_and_refused_sub_functions(rig, transport):
    r = rig(transport)
    r.step_aside()  # pymodbus's serial client opens the port for exclusive use too
    if transport == "tcp":
        host, port = r.server.endpoint.rsplit(":", 1)
        client = ModbusTcpClient(host, port=int(port), timeout=1, retries=0)
    else:
        client = ModbusSerialClient(r.server.endpoint, baudrate=115200, timeout=1, retries=0)
    try:
        assert client.connect()
        echo = client.diag_query_data(b"\x12\x34", device_id=DETECTOR_UNIT)
        assert not echo.isError() and echo.message == b"\x12\x34"
        cleared = client.diag_clear_counters(device_id=DETECTOR_UNIT)
        assert cleared.isError() and cleared.exception_code == ILLEGAL_FUNCTION
        status = client.read_exception_status(device_id=STAGE_UNIT)
        assert status.isError() and status.exception_code == ILLEGAL_FUNCTION
    finally:
        client.close()
