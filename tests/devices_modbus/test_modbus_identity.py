"""Device identity over Modbus: the register map's [identity] strings (both readers, bad
tables), the emulators' Read Device Identification (function 43 / MEI 14) to a third-party
client, and the drivers' identity(): 43/14 first, the registers as fallback, else none."""

import math
import re

import pytest
from modbus_testkit import DETECTOR_MAP, STAGE_MAP, endpoint_args  # noqa: I001

from drivers.modbus_detector import ModbusDetector
from drivers.modbus_stage import ModbusStage
from drivers.modbus_transport import ModbusTimeouts
from drivers.register_map import RegisterMap, RegisterMapError, decode_text
from sim.devices.modbus_detector import ModbusDetectorEmulator
from sim.devices.modbus_server import FIRMWARE, ModbusEmulatorServer
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.register_map import DeviceLayout, LayoutError

TRANSPORTS = ["tcp", "rtu"]


def with_identity(src, folder, identity: str | None, name: str = "map"):
    """A copy of a shipped map whose [identity] table is replaced (None: no table)."""
    text = src.read_text().split("\n[identity]\n")[0]
    path = folder / f"{name}.toml"
    path.write_text(text + ("" if identity is None else f"\n[identity]\n{identity}\n"))
    return path


def stage_unit(stage_map, **kw):
    return ModbusStageEmulator(VirtualClock(math.inf), stage_map, (-95.0, 95.0), 20.0, 80.0,
                               **kw)


@pytest.fixture
def serve():
    """serve(transport, {unit id: emulator}) -> (server, driver kwargs); stopped after."""
    servers = []

    def start(transport, units):
        server = ModbusEmulatorServer(transport, units)
        server.start()
        servers.append(server)
        kind, where, kw = endpoint_args(server)
        return kind, where, kw

    yield start
    for server in servers:
        server.stop()


def test_both_readers_agree_on_the_identity_strings():
    for path in (STAGE_MAP, DETECTOR_MAP):
        host, emu = RegisterMap.load(path), DeviceLayout.read(path)
        assert set(host.identity) == set(emu.identity) == {"vendor", "model", "serial",
                                                           "firmware"}
        for name, reg in host.identity.items():
            f = emu.identity[name]
            assert (reg.table, reg.address, reg.count) == (f.table, f.address, f.width)
            assert not f.writable


@pytest.mark.parametrize("table, message", [
    ('serial = 5', "[identity.serial]: must be a table"),
    ('serial = { table = "holding", address = 100, count = 4, kind = "x" }',
     "[identity.serial]: unknown key 'kind'"),
    ('serial = { table = "coils", address = 100, count = 4 }',
     "[identity.serial]: table must be one of holding, input, got 'coils'"),
    ('serial = { table = "holding", address = 100 }', "[identity.serial]: missing field 'count'"),
    ('serial = { table = "holding", address = 100, count = 0 }',
     "[identity.serial]: count must be 1..125"),
    ('serial = { table = "holding", address = -1, count = 4 }',
     "[identity.serial]: address must be an integer >= 0"),
    ('serial = { table = "holding", address = 65534, count = 4 }',
     "past the 16-bit address space"),
    ('serial = { table = "holding", address = 12, count = 2 }',
     "registers 'limit_negative' and 'identity.serial' overlap at holding address 12"),
    ('model = { table = "holding", address = 100, count = 4 }\n'
     'serial = { table = "holding", address = 103, count = 4 }',
     "registers 'identity.model' and 'identity.serial' overlap at holding address 103"),
])
def test_a_bad_identity_table_names_the_file_and_key(tmp_path, table, message):
    path = with_identity(STAGE_MAP, tmp_path, table)
    with pytest.raises(RegisterMapError) as err:
        RegisterMap.load(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("table", [
    'serial = { table = "coils", address = 100, count = 4 }',
    'serial = { table = "holding", address = 100 }',
    'serial = { table = "holding", address = 12, count = 2 }',
])
def test_the_emulator_refuses_a_bad_identity_table_too(tmp_path, table):
    path = with_identity(STAGE_MAP, tmp_path, table)
    with pytest.raises(LayoutError, match=f"^{re.escape(str(path))}: .*serial"):
        stage_unit(path)


def test_identity_registers_hold_ascii_two_characters_each(tmp_path):
    path = with_identity(STAGE_MAP, tmp_path, 'serial = { table = "holding", address = 100, '
                                              'count = 3 }')
    unit = stage_unit(path, serial="AB1234567")  # cut to the 6 characters the map gives
    words = unit.registers.read("holding", 100, 3)
    assert words == [0x4142, 0x3132, 0x3334]
    assert decode_text(words) == "AB1234"
    assert decode_text([0x2041, 0x4200, 0x0000]) == "AB"  # padding dropped at either end
    assert decode_text(b"\x00OK\xff") == "OK\ufffd"


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_identity_by_device_identification_and_registers(serve, transport):
    """Each unit answers 43/14 with its own vendor, model and firmware; the serial (not a
    basic object) comes from the registers and differs per unit."""
    clock = VirtualClock(math.inf)
    units = {1: ModbusStageEmulator(clock, STAGE_MAP, (-95.0, 95.0), 20.0, 80.0),
             2: ModbusStageEmulator(clock, STAGE_MAP, (-95.0, 95.0), 20.0, 80.0),
             3: ModbusDetectorEmulator(ConstantPower(1e-5), DETECTOR_MAP, serial="PD-0042")}
    kind, where, kw = serve(transport, units)
    seen = {}
    for unit, driver, path in ((1, ModbusStage, STAGE_MAP), (2, ModbusStage, STAGE_MAP),
                               (3, ModbusDetector, DETECTOR_MAP)):
        with driver(kind, where, unit, path, name=f"unit{unit}", **kw) as drv:
            seen[unit] = drv.identity()
    for unit in (1, 2):
        assert seen[unit] == {"vendor": "Example Motion Co", "model": "stepper-drive",
                              "firmware": FIRMWARE, "serial": units[unit].identity["serial"]}
    assert seen[1]["serial"] != seen[2]["serial"]
    assert seen[3] == {"vendor": "Example Photonics", "model": "photodiode-adc",
                       "firmware": FIRMWARE, "serial": "PD-0042"}


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_identity_falls_back_to_the_registers_then_to_none(serve, transport, tmp_path):
    """The map below names only model and serial registers: with 43/14 the vendor and
    firmware come too; without it only the registers' strings; with neither, nothing."""
    partial = with_identity(STAGE_MAP, tmp_path, 'model = { table = "holding", address = 100, '
                            'count = 8 }\nserial = { table = "input", address = 0, count = 4 }',
                            "partial")
    bare = with_identity(STAGE_MAP, tmp_path, None, "bare")
    units = {1: stage_unit(partial, serial="S1"),
             2: stage_unit(partial, serial="S2", device_identification=False),
             3: stage_unit(bare, device_identification=False),
             4: stage_unit(bare)}
    kind, where, kw = serve(transport, units)
    found = {}
    for unit, path in ((1, partial), (2, partial), (3, bare), (4, bare)):
        with ModbusStage(kind, where, unit, path, name=f"unit{unit}",
                         timeouts=ModbusTimeouts(reply_s=0.3), **kw) as st:
            found[unit] = st.identity()
            assert st.position() == 0.0  # the link is in step after a refused 43/14
    assert found[1] == {"vendor": "Example Motion Co", "model": "stepper-drive",
                        "firmware": FIRMWARE, "serial": "S1"}
    assert found[2] == {"model": "stepper-drive", "serial": "S2"}
    assert found[3] == {}
    assert found[4] == {"vendor": "Example Motion Co", "model": "stepper-drive",
                        "firmware": FIRMWARE}


def test_a_third_party_client_reads_device_identification(serve):
    from pymodbus.client import ModbusTcpClient

    units = {1: stage_unit(STAGE_MAP), 2: stage_unit(STAGE_MAP, device_identification=False),
             3: ModbusDetectorEmulator(ConstantPower(1e-5), DETECTOR_MAP)}
    _, host, kw = serve("tcp", units)
    client = ModbusTcpClient(host, port=kw["tcp_port"])
    assert client.connect()
    try:
        basic = client.read_device_information(device_id=1)
        assert basic.information == {0: b"Example Motion Co", 1: b"stepper-drive",
                                     2: FIRMWARE.encode()}
        assert basic.conformity == 0x81  # basic objects, stream and individual access
        regular = client.read_device_information(read_code=2, device_id=3)  # basic only here
        assert regular.information[1] == b"photodiode-adc" and len(regular.information) == 3
        one = client.read_device_information(read_code=4, object_id=2, device_id=3)
        assert one.information == {2: FIRMWARE.encode()}
        from_two = client.read_device_information(read_code=1, object_id=2, device_id=1)
        assert list(from_two.information) == [2]
        absent = client.read_device_information(read_code=4, object_id=5, device_id=1)
        assert absent.isError() and absent.exception_code == 2
        refused = client.read_device_information(device_id=2)
        assert refused.isError() and refused.exception_code == 1
        serial = client.read_holding_registers(132, count=8, device_id=1)
        assert decode_text(serial.registers) == units[1].identity["serial"]
    finally:
        client.close()
