"""Bad bytes into the Modbus emulators (random, truncated, wrong CRC, over-long) over a real pty
and a real socket: every reply is a well-formed frame (an exception reply for bad requests) or
silence, the server never crashes, and a good request afterwards gets the right answer."""

import math
import socket
import struct

import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from modbus_testkit import DETECTOR_MAP, STAGE_MAP, crc16  # noqa: I001 - the test folder's own fixtures

from drivers.modbus_stage import ModbusStage
from sim.devices.modbus_detector import ModbusDetectorEmulator
from sim.devices.modbus_server import ModbusEmulatorServer
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower

FUZZ = settings(max_examples=50, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])
ALLOWED_EXCEPTIONS = {1, 2, 3, 11}  # 04 would mean a unit failed inside


@st.composite
def pdus(draw):
    """A request PDU: a plausible read or write, or any function with any data."""
    function = draw(st.sampled_from([3, 4, 6, 16, 1, 5, 23, 43, 0x7F, 0x90]))
    address = draw(st.integers(0, 0xFFFF))
    if function in (3, 4):
        return struct.pack(">BHH", function, address, draw(st.integers(0, 300)))
    if function == 6:
        return struct.pack(">BHH", function, address, draw(st.integers(0, 0xFFFF)))
    if function == 16:
        values = draw(st.lists(st.integers(0, 0xFFFF), min_size=0, max_size=8))
        count = draw(st.sampled_from([len(values), len(values) + 1, 200]))
        return struct.pack(f">BHHB{len(values)}H", 16, address, count, 2 * len(values), *values)
    return bytes([function]) + draw(st.binary(max_size=12))


@st.composite
def rtu_inputs(draw):
    """(bytes, kind): random / truncated / wrong CRC / over-long / good, around units 1, 2, 9."""
    frame = bytes([draw(st.sampled_from([1, 2, 9]))]) + draw(pdus())
    frame += crc16(frame)
    kind = draw(st.sampled_from(["random", "truncated", "bad_crc", "overlong", "good"]))
    if kind == "random":
        return draw(st.binary(min_size=1, max_size=300)), kind
    if kind == "truncated":
        return frame[:draw(st.integers(1, len(frame) - 1))], kind
    if kind == "bad_crc":
        return frame[:-2] + bytes([frame[-2] ^ draw(st.integers(1, 255)), frame[-1]]), kind
    if kind == "overlong":
        return frame + draw(st.binary(min_size=1, max_size=300)), kind
    return frame, kind


def make_server(transport):
    clock = VirtualClock(math.inf)
    units = {1: ModbusStageEmulator(clock, STAGE_MAP, (-95.0, 95.0), 20.0, 80.0),
             2: ModbusDetectorEmulator(ConstantPower(1e-6), DETECTOR_MAP)}
    server = ModbusEmulatorServer(transport, units)
    server.start()
    return server


def rtu_frames(reply: bytes) -> list[bytes]:
    """Split a reply stream into frames by their length rules; ValueError if malformed."""
    frames = []
    while reply:
        function = reply[1] if len(reply) > 1 else 0
        if function & 0x80:
            size = 5
        elif function in (3, 4, 23):
            size = 5 + reply[2] if len(reply) > 2 else 99999
        elif function in (6, 16):
            size = 8
        else:  # pymodbus's own functions (e.g. 43): the whole rest must check out
            size = len(reply)
        frame, reply = reply[:size], reply[size:]
        if len(frame) != size or crc16(frame[:-2]) != frame[-2:]:
            raise ValueError(f"malformed reply frame {frame.hex()}")
        frames.append(frame)
    return frames


def check_healthy(server):
    """The server still runs and answers a good request with the right value."""
    assert server._thread.is_alive()
    transport = server.transport
    host, port = (server.endpoint.rsplit(":", 1) if transport == "tcp"
                  else (server.endpoint, "502"))
    with ModbusStage(transport, host, 1, STAGE_MAP, tcp_port=int(port), name="after") as stage:
        stage.move_to(12.0)
        assert stage.wait(1.0) == 12.0
        assert stage.limits() == (-95.0, 95.0)


def test_rtu_emulator_survives_bad_frames():
    server = make_server("rtu")
    try:
        port = serial.Serial(server.endpoint, 115200, timeout=0.05)

        @FUZZ
        @given(rtu_inputs())
        def check(case):
            data, kind = case
            port.write(data)
            reply = b""
            while chunk := port.read(1024):  # until the line has been quiet for 50 ms
                reply += chunk
            frames = rtu_frames(reply)
            if kind in ("truncated", "bad_crc"):
                assert frames == [], (kind, data.hex(), reply.hex())
            for frame in frames:
                assert frame[0] in (1, 2)  # only present units answer; unit 9 is silent
                if frame[1] & 0x80:
                    assert frame[2] in ALLOWED_EXCEPTIONS, frame.hex()

        check()
        port.close()
        check_healthy(server)
    finally:
        server.stop()


@st.composite
def tcp_inputs(draw):
    """Bytes for one TCP connection: an MBAP frame (honest or lying length, any protocol
    id), truncated, over-long, or random."""
    pdu = draw(pdus())
    length = draw(st.sampled_from([len(pdu) + 1, 0, 1, 300, 0xFFFF]))
    protocol = draw(st.sampled_from([0, 0, 1]))
    frame = struct.pack(">HHHB", draw(st.integers(0, 0xFFFF)), protocol, length,
                        draw(st.sampled_from([1, 2, 9, 0]))) + pdu
    kind = draw(st.sampled_from(["frame", "truncated", "overlong", "random"]))
    if kind == "truncated":
        return frame[:draw(st.integers(1, len(frame) - 1))]
    if kind == "overlong":
        return frame + draw(st.binary(min_size=1, max_size=600))
    if kind == "random":
        return draw(st.binary(min_size=1, max_size=600))
    return frame


def test_tcp_emulator_survives_bad_frames():
    server = make_server("tcp")
    host, port = server.endpoint.rsplit(":", 1)
    try:
        @FUZZ
        @given(tcp_inputs())
        def check(data):
            with socket.create_connection((host, int(port)), timeout=1.0) as sock:
                sock.sendall(data)
                sock.settimeout(0.02)
                reply = b""
                try:
                    while chunk := sock.recv(4096):
                        reply += chunk
                except (TimeoutError, ConnectionResetError):
                    pass
            while reply:  # every reply is a whole MBAP frame with a sane PDU
                assert len(reply) >= 9, reply.hex()
                _, protocol, length, _ = struct.unpack(">HHHB", reply[:7])
                assert protocol == 0 and len(reply) >= 6 + length, reply.hex()
                function = reply[7]
                if function & 0x80:
                    assert reply[8] in ALLOWED_EXCEPTIONS, reply.hex()
                reply = reply[6 + length:]

        check()
        check_healthy(server)
    finally:
        server.stop()
