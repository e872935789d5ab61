"""Fault injector (seeded, validated) and the pty server, over a real pseudo-terminal."""

import os
import time

import pytest
import serial
from waiting import wait_until

from sim.devices.faults import FaultConfigError, FaultInjector, FaultSpec
from sim.devices.pty_server import PtyServer


def test_faultspec_unknown_key_is_named():
    with pytest.raises(FaultConfigError,
                       match=r"\[sim\.faults\.esp\]: unknown key 'drop_probability'"):
        FaultSpec.from_dict({"drop_probability": 0.1}, device="esp")


@pytest.mark.parametrize(
    "table, field",
    [
        ({"stall_prob": 1.5}, "stall_prob"),
        ({"latency_s": -1}, "latency_s"),
        ({"disconnect_after": 2.5}, "disconnect_after"),
        ({"seed": "x"}, "seed"),
        ({"latency_s": True}, "latency_s"),
        ({"drop_prob": "0.1"}, "drop_prob"),
    ],
)
def test_faultspec_bad_values_are_named(table, field):
    with pytest.raises(FaultConfigError, match=rf"\[sim\.faults\.pm\] {field}: "):
        FaultSpec.from_dict(table, device="pm")


def test_injector_is_seeded_and_rates_match():
    spec = FaultSpec(drop_prob=0.2, corrupt_prob=0.1, stall_prob=0.05, seed=7)
    runs = []
    for _ in range(2):
        inj = FaultInjector(spec)
        runs.append([inj.reply(b"12.345\r\n", keep_tail=2) for _ in range(4000)])
        counts = inj.counts
    assert runs[0] == runs[1]
    # binomial counts within 5 sigma of the configured rates
    n = 4000
    for kind, p, trials in [("stall", 0.05, n), ("drop", 0.2, n - counts["stall"])]:
        assert abs(counts[kind] - p * trials) < 5 * (p * (1 - p) * trials) ** 0.5
    for out in runs[0]:
        assert out is None or out.endswith(b"\r\n")  # the terminator is kept


def test_injector_each_fault_kind():
    assert FaultInjector(FaultSpec(stall_prob=1.0)).reply(b"abc\n") is None
    assert len(FaultInjector(FaultSpec(drop_prob=1.0)).reply(b"abc\n", keep_tail=1)) == 3
    bad = FaultInjector(FaultSpec(corrupt_prob=1.0)).reply(b"abc\n", keep_tail=1)
    assert sum(b >= 0x80 for b in bad) == 1 and bad.endswith(b"\n")
    crc = FaultInjector(FaultSpec(bad_crc_prob=1.0)).reply(b"\x01\x03\x00\x00", crc_bytes=2)
    assert crc[:3] == b"\x01\x03\x00" and crc[3] != 0
    inj = FaultInjector(FaultSpec(disconnect_after=2))
    inj.reply(b"a")
    assert not inj.should_disconnect()
    inj.reply(b"b")
    assert inj.should_disconnect()
    assert FaultInjector(FaultSpec(latency_s=0.25)).delay() == 0.25
    assert not FaultSpec().active and FaultSpec(stall_prob=0.1).active


def echo_upper(line: bytes) -> bytes:
    if line == b"BOOM":
        raise RuntimeError("handler bug")
    return line.upper() + b"\r\n"


def test_pty_server_lines_overflow_and_handler_bug():
    server = PtyServer(
        echo_upper, terminators=b"\r", ignore=b"\n", max_line=8,
        on_overflow=lambda: b"OVERFLOW\r\n", reply_tail=2,
    )
    endpoint = server.start()
    try:
        assert endpoint.startswith("/dev/pts/")
        with serial.Serial(endpoint, 19200, timeout=2.0) as port:
            port.write(b"ab\r\ncd\r")
            assert port.read_until(b"\r\n") == b"AB\r\n"
            assert port.read_until(b"\r\n") == b"CD\r\n"
            port.write(b"0123456789abcdef\rok\r")
            assert port.read_until(b"\r\n") == b"OVERFLOW\r\n"
            assert port.read_until(b"\r\n") == b"OK\r\n"
            port.write(b"BOOM\rx\r")
            assert port.read_until(b"\r\n") == b"X\r\n"
        assert len(server.handler_errors) == 1
    finally:
        server.stop()
    assert not os.path.exists(endpoint) or server.endpoint == endpoint


def test_pty_server_frame_mode_and_disconnect():
    server = PtyServer(
        lambda frame: frame[::-1], terminators=None, frame_gap_s=0.01,
        faults=FaultInjector(FaultSpec(disconnect_after=1)),
    )
    endpoint = server.start()
    try:
        with serial.Serial(endpoint, 19200, timeout=1.0) as port:
            port.write(b"\x01\x02\x03")
            assert port.read(3) == b"\x03\x02\x01"
            wait_until(lambda: server.disconnected, what="the server's disconnect")
            with pytest.raises(serial.SerialException):
                port.write(b"\x01")
                port.read(1)
    finally:
        server.stop()


def test_pty_server_latency_is_applied():
    server = PtyServer(echo_upper, faults=FaultInjector(FaultSpec(latency_s=0.1)))
    endpoint = server.start()
    try:
        with serial.Serial(endpoint, 19200, timeout=2.0) as port:
            t0 = time.monotonic()
            port.write(b"hi\r")
            assert port.read_until(b"\r\n") == b"HI\r\n"
            assert time.monotonic() - t0 >= 0.1
    finally:
        server.stop()
