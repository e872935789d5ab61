"""Third-party Modbus masters drive the emulators: mbpoll (libmodbus, Debian) and pymodbus's
own client, over TCP on 127.0.0.1 and RTU on the pty, in both word orders of the maps."""

import re
import subprocess

import pytest
from pymodbus.client import ModbusSerialClient, ModbusTcpClient

pytestmark = pytest.mark.thirdparty


def run_mbpoll(path, server, word_order, unit, kind, ref, count=1, values=()):
    """Run mbpoll once against the server; returns (return code, {address: text value})."""
    cmd = [path, "-a", str(unit), "-0", "-r", str(ref), "-t", kind, "-1", "-o", "1"]
    if not values:
        cmd += ["-c", str(count)]
    if word_order == "big" and ":" in kind:
        cmd.append("-B")
    if server.transport == "tcp":
        host, port = server.endpoint.rsplit(":", 1)
        cmd += ["-m", "tcp", "-p", port, host]
    else:
        cmd += ["-m", "rtu", "-b", "115200", "-P", "none", server.endpoint]
    if values:
        cmd += ["--", *[str(v) for v in values]]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=20)
    found = re.findall(r"^\[(\d+)\]:\s+(\S+)", done.stdout, re.MULTILINE)
    return done.returncode, {int(a): v for a, v in found}, done.stdout + done.stderr


def test_mbpoll_reads_every_stage_register_as_the_emulator_holds_it(rig, link, mbpoll):
    r = rig(*link)
    rc, got, out = run_mbpoll(mbpoll, r.server, link[1], 1, "4", 0, 15)
    assert rc == 0, out
    words = r.stage_emu.registers.read("holding", 0, 15)
    assert [int(got[a]) for a in range(15)] == words
    rc, got, out = run_mbpoll(mbpoll, r.server, link[1], 1, "4:int", 2)  # velocity, 32 bit
    assert rc == 0 and int(got[2]) == 20000, out  # 20 deg/s in millidegrees


def test_mbpoll_writes_a_target_and_starts_the_move(rig, link, mbpoll):
    r = rig(*link)
    rc, _, out = run_mbpoll(mbpoll, r.server, link[1], 1, "4:int", 0, values=[-30125])
    assert rc == 0, out
    rc, _, out = run_mbpoll(mbpoll, r.server, link[1], 1, "4", 6, values=[1])  # start
    assert rc == 0, out
    assert r.stage_emu.axis_position_deg() == -30.125
    rc, got, out = run_mbpoll(mbpoll, r.server, link[1], 1, "4:int", 8)
    assert rc == 0 and int(got[8]) == -30125, out
    assert r.stage.position() == -30.125  # and our own driver agrees


def test_mbpoll_configures_and_reads_the_detector(rig, link, mbpoll):
    r = rig(*link)
    rc, _, out = run_mbpoll(mbpoll, r.server, link[1], 2, "4", 0, values=[4, 0, 8])
    assert rc == 0, out  # gain range 4 (1e-4 W), autorange off, averaging 8
    assert r.detector.settings()["averaging"] == 8.0
    rc, got, out = run_mbpoll(mbpoll, r.server, link[1], 2, "3:float", 0)
    assert rc == 0 and float(got[0]) == pytest.approx(1e-5, rel=2e-3), out
    rc, got, out = run_mbpoll(mbpoll, r.server, link[1], 2, "3", 2, 3)
    assert rc == 0 and [int(got[a]) for a in (2, 3, 4)] == [0, 4, 0], out  # status, range, fault


def test_mbpoll_sees_exception_replies_and_bus_silence(rig, mbpoll):
    r = rig("rtu")
    rc, _, out = run_mbpoll(mbpoll, r.server, "big", 1, "4", 10, values=[5])
    assert rc != 0 and "Illegal data address" in out
    rc, _, out = run_mbpoll(mbpoll, r.server, "big", 2, "4", 2, values=[0])
    assert rc != 0 and "Illegal data value" in out
    rc, _, out = run_mbpoll(mbpoll, r.server, "big", 9, "4", 0)
    assert rc != 0 and "timed out" in out  # no unit 9 on the bus


def pymodbus_client(server):
    if server.transport == "tcp":
        host, port = server.endpoint.rsplit(":", 1)
        return ModbusTcpClient(host, port=int(port), timeout=1, retries=0)
    return ModbusSerialClient(server.endpoint, baudrate=115200, timeout=1, retries=0)


def test_pymodbus_client_reads_and_writes_both_emulators(rig, link):
    r = rig(*link)
    r.step_aside()  # pymodbus's serial client opens the port for exclusive use too
    order = link[1]
    client = pymodbus_client(r.server)
    try:
        assert client.connect()
        int32 = client.DATATYPE.INT32
        words = client.convert_to_registers(45250, int32, word_order=order)
        assert not client.write_registers(0, words, device_id=1).isError()
        assert not client.write_register(6, 1, device_id=1).isError()  # start (function 06)
        got = client.read_holding_registers(8, count=3, device_id=1)
        assert client.convert_from_registers(got.registers[:2], int32, word_order=order) == 45250
        assert got.registers[2] == 0  # status: at rest, not homed, no fault
        reading = client.read_input_registers(0, count=2, device_id=2)
        power = client.convert_from_registers(reading.registers, client.DATATYPE.FLOAT32,
                                              word_order=order)
        assert power == pytest.approx(1e-5, rel=5e-3)  # read noise: 1e-3 per sample
        bad = client.write_register(0, 99, device_id=2)  # gain range past the table
        assert bad.isError() and bad.exception_code == 3
        assert client.read_coils(0, count=1, device_id=1).exception_code == 1
        both = client.readwrite_registers(read_address=2, read_count=1, write_address=2,
                                          values=[16], device_id=2)  # function 23
        assert both.registers == [16]  # averaging set and read back in one request
    finally:
        client.close()
    r.step_back()
    assert r.stage.position() == 45.25
