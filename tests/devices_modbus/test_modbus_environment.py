"""The XY-MD02 temperature and humidity transmitter: its emulator answers the manual's own
frames byte for byte on a real pty, gonio's driver and third-party masters (pymodbus's client,
mbpoll) read it over RTU and TCP, and what the manual leaves to Modbus (exceptions) holds."""

import subprocess

import pytest
import serial
from modbus_testkit import MAPS, crc16, endpoint_args
from pymodbus.client import ModbusSerialClient, ModbusTcpClient

from drivers.base import DeviceError
from drivers.modbus_environment import ModbusEnvironment
from drivers.modbus_transport import ModbusTimeouts
from sim.devices.modbus_environment import ModbusEnvironmentEmulator
from sim.devices.modbus_server import ModbusEmulatorServer

XY_MD02 = MAPS / "xy-md02.toml"


class Air:
    """The room the emulated sensor reads: set by the test."""

    def __init__(self, temperature_c: float = 21.0, humidity_rel: float = 0.45):
        self.temperature_c, self.humidity_rel = temperature_c, humidity_rel

    def __call__(self) -> tuple[float, float]:
        return self.temperature_c, self.humidity_rel


@pytest.fixture
def sensor():
    """An emulated XY-MD02 at unit 1 on a server of the transport asked; yields (server,
    emulator, air); stops it after."""
    servers = []

    def make(transport: str, baudrate: int = 9600):
        air = Air()
        emu = ModbusEnvironmentEmulator(air, XY_MD02)
        server = ModbusEmulatorServer(transport, {1: emu}, baudrate=baudrate)
        server.start()
        servers.append(server)
        return server, emu, air

    yield make
    for server in servers:
        server.stop()


def driver(server: ModbusEmulatorServer) -> ModbusEnvironment:
    transport, where, kwargs = endpoint_args(server)
    return ModbusEnvironment(transport, where, 1, XY_MD02,
                             timeouts=ModbusTimeouts(reply_s=1.0), **kwargs)


def exchange(port: str, request: bytes, reply_bytes: int) -> bytes:
    """Send raw bytes on the emulator's pty and read the reply: no Modbus library between."""
    with serial.Serial(port, 9600, timeout=2.0) as line:
        line.write(request)
        return line.read(reply_bytes)


def test_the_manuals_temperature_frame_is_answered_byte_for_byte(sensor):
    server, _, air = sensor("rtu")
    air.temperature_c = 30.5
    request = bytes.fromhex("01 04 00 01 00 01 60 0A")  # the manual's: read the temperature
    assert crc16(request[:-2]) == request[-2:]
    assert exchange(server.endpoint, request, 7) == bytes.fromhex("01 04 02 01 31 79 74")


def test_negative_temperatures_and_humidity_are_the_manuals_words(sensor):
    server, _, air = sensor("rtu")
    air.temperature_c, air.humidity_rel = -20.5, 0.546
    request = bytes.fromhex("01 04 00 01 00 02")
    request += crc16(request)
    reply = exchange(server.endpoint, request, 9)
    assert reply[:3] == bytes.fromhex("01 04 04")
    assert reply[3:7] == bytes.fromhex("FF 33 02 22")  # -205 and 546, as the manual says
    assert reply[7:] == crc16(reply[:7])


@pytest.mark.parametrize("transport", ["rtu", "tcp"])
def test_the_driver_reads_the_room_in_degrees_and_a_fraction(sensor, transport):
    server, _, air = sensor(transport)
    air.temperature_c, air.humidity_rel = -20.5, 0.546
    with driver(server) as room:
        got = room.read_room()
        assert (got.temperature_c, got.humidity_rel) == (-20.5, 0.546)
        air.temperature_c, air.humidity_rel = 23.46, 0.4049  # 0.1 degC and 0.1 %RH steps
        got = room.read_room()
        assert (got.temperature_c, got.humidity_rel) == (23.5, 0.405)
        assert room.identity() == {}  # no function 43, no identity registers


def test_corrections_are_added_and_a_correction_out_of_range_is_refused(sensor):
    server, _, air = sensor("tcp")
    air.temperature_c, air.humidity_rel = 20.0, 0.5
    host, port = server.endpoint.rsplit(":", 1)
    client = ModbusTcpClient(host, port=int(port), timeout=1, retries=0)
    try:
        assert client.connect()
        assert not client.write_register(0x0103, 0xFFF6, device_id=1).isError()  # -1.0 degC
        assert not client.write_register(0x0104, 25, device_id=1).isError()  # +2.5 %RH
        got = client.read_input_registers(1, count=2, device_id=1)
        assert got.registers == [190, 525]
        held = client.read_holding_registers(0x0101, count=4, device_id=1)
        assert held.registers == [1, 0, 0xFFF6, 25]  # address 1, 9600 baud, the corrections
        bad = client.write_register(0x0103, 101, device_id=1)  # +10.1 degC: past +-10.0
        assert bad.isError() and bad.exception_code == 3
        bad = client.write_register(0x0102, 3, device_id=1)  # no baud code 3
        assert bad.isError() and bad.exception_code == 3
        missing = client.read_input_registers(3, count=1, device_id=1)
        assert missing.isError() and missing.exception_code == 2
    finally:
        client.close()


def test_a_reading_no_room_can_have_is_a_device_error(sensor):
    server, _, air = sensor("tcp")
    air.temperature_c = 150.0
    with driver(server) as room, pytest.raises(DeviceError, match="no room temperature"):
        room.read_room()


def test_pymodbus_serial_client_reads_the_sensor_at_its_factory_line(sensor):
    server, _, air = sensor("rtu")
    air.temperature_c, air.humidity_rel = 24.2, 0.383
    client = ModbusSerialClient(server.endpoint, baudrate=9600, parity="N", timeout=1,
                                retries=0)
    try:
        assert client.connect()
        got = client.read_input_registers(1, count=2, device_id=1)
        assert got.registers == [242, 383]
    finally:
        client.close()


@pytest.mark.thirdparty
def test_mbpoll_reads_temperature_and_humidity_over_rtu(sensor, mbpoll):
    server, _, air = sensor("rtu")
    air.temperature_c, air.humidity_rel = -3.7, 0.612
    # input registers 1 and 2 (mbpoll -0: protocol addresses); mbpoll shows a word whose top
    # bit is set both unsigned and signed
    done = subprocess.run([mbpoll, "-a", "1", "-0", "-r", "1", "-c", "2", "-t", "3", "-1",
                           "-o", "1", "-m", "rtu", "-b", "9600", "-P", "none",
                           server.endpoint], capture_output=True, text=True, timeout=20)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "[1]: \t65499 (-37)\n" in done.stdout and "[2]: \t612\n" in done.stdout, done.stdout
