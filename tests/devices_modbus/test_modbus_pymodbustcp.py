"""pyModbusTCP (a Modbus TCP client with its own framing and word helpers) drives both
emulators over TCP on 127.0.0.1 as a lab's own script would, from the register map read with
tomllib: identity by Read Device Identification (43/14) and the registers, position and
status, a move polled to its end on the drive's virtual clock, the amplifier's power in a
fixed gain range, and exception replies with the codes the library reports."""

import pytest
from lab_script import (  # noqa: I001 - the test folder's own helpers
    SPEC_EXCEPTIONS,
    LabMap,
    ascii_of,
    check_move,
    moving_polls,
    poll_move,
)
from modbus_testkit import DETECTOR_UNIT, STAGE_UNIT

from sim.devices.motion import VirtualClock

pyModbusTCP = pytest.importorskip(
    "pyModbusTCP", reason="pyModbusTCP is not installed (pip install -e '.[clients]')")
from pyModbusTCP import utils  # noqa: E402
from pyModbusTCP.client import ModbusClient  # noqa: E402
from pyModbusTCP.constants import MB_EXCEPT_ERR  # noqa: E402

pytestmark = pytest.mark.thirdparty


@pytest.fixture
def server(rig, word_order):
    """(rig, stage map, detector map, client maker): the emulators on TCP, the drive on a
    frozen clock; every client made is closed after the test."""
    r = rig("tcp", word_order, clock=VirtualClock(0.0))
    host, port = r.server.endpoint.rsplit(":", 1)
    made = []

    def client(unit: int) -> ModbusClient:
        made.append(ModbusClient(host, int(port), unit_id=unit, timeout=2.0))
        return made[-1]

    yield r, LabMap.load(r.stage_map), LabMap.load(r.detector_map), client
    for c in made:
        c.close()


def int32(lab: LabMap, words: list[int]) -> int:
    """A signed 32-bit value from its two registers in the map's word order."""
    return utils.get_2comp(utils.word_list_to_long(words, big_endian=lab.big_endian)[0], 32)


def words32(lab: LabMap, value: int) -> list[int]:
    """The two registers of a 32-bit value in the map's word order."""
    return utils.long_list_to_word([value], big_endian=lab.big_endian)


def test_pymodbustcp_reads_identity_position_and_limits(server):
    r, drive_map, amp_map, client = server
    drive, amp = client(STAGE_UNIT), client(DETECTOR_UNIT)
    basic = drive.read_device_identification()  # 43/14, read code 1: the basic objects
    assert ascii_of(basic.vendor_name) == drive_map.doc["vendor"]
    assert ascii_of(basic.product_code) == drive_map.doc["name"]
    firmware = drive.read_holding_registers(*drive_map.identity("firmware"))
    assert ascii_of(basic.major_minor_revision) == ascii_of(firmware) != ""
    one = amp.read_device_identification(read_code=4, object_id=1)  # one object: product code
    assert {k: ascii_of(v) for k, v in one.objects_by_id.items()} == {1: amp_map.doc["name"]}
    serials = {ascii_of(drive.read_holding_registers(*drive_map.identity("serial"))),
               ascii_of(amp.read_input_registers(*amp_map.identity("serial")))}
    assert len(serials) == 2 and "" not in serials  # one serial per unit, not a basic object

    def read_deg(name):
        raw = int32(drive_map, drive.read_holding_registers(drive_map.address(name), 2))
        return drive_map.value(name, raw)

    assert read_deg("actual_position") == 0.0
    assert (read_deg("limit_negative"), read_deg("limit_positive")) == (-95.0, 95.0)
    assert drive.read_holding_registers(drive_map.address("status")) == [0]
    assert r.stage_emu.axis_position_deg() == 0.0


def test_pymodbustcp_sets_speed_and_moves_to_a_target_polled_to_its_end(server):
    r, lab, _, client = server
    drive = client(STAGE_UNIT)
    for name, value in (("velocity", 12.5), ("acceleration", 50.0), ("target_position", 30.0)):
        assert drive.write_multiple_registers(lab.address(name),
                                              words32(lab, lab.raw(name, value)))
    assert drive.write_single_register(lab.address("command"), lab.command("start"))
    polls, positions = poll_move(
        lab, lambda: drive.read_holding_registers(lab.address("status"))[0],
        lambda: lab.value("actual_position", int32(lab, drive.read_holding_registers(
            lab.address("actual_position"), 2))),
        r.stage_emu.axis.clock)
    assert polls == moving_polls(30.0, 12.5, 50.0) == 11  # 7 at the power-on 20 deg/s
    check_move(positions, 0.0, 30.0)
    assert drive.read_holding_registers(lab.address("fault_code")) == [0]
    assert r.stage_emu.axis_position_deg() == 30.0


def test_pymodbustcp_reads_the_power_in_a_fixed_gain_range(server):
    _, _, lab, client = server
    amp = client(DETECTOR_UNIT)
    for name, value in (("autorange", 0), ("gain_range", 4), ("averaging", 8)):
        assert amp.write_single_register(lab.address(name), value)
    assert amp.read_holding_registers(lab.address("averaging")) == [8]
    words = amp.read_input_registers(lab.address("reading"), 5)  # reading .. fault_code

    def power_of(words):
        raw = utils.word_list_to_long(words[:2], big_endian=lab.big_endian)[0]
        return utils.decode_ieee(raw)

    power = power_of(words)
    assert words[2:] == [0, 4, 0]  # status, range in use, fault code
    assert power == pytest.approx(1e-5, rel=5e-3)  # ConstantPower(1e-5), read noise 1e-3
    assert power < lab.doc["gain_ranges"]["full_scale_w"][4]
    assert amp.write_single_register(lab.address("gain_range"), 2)  # 1e-6 W full scale
    clipped = amp.read_input_registers(lab.address("reading"), 5)
    assert clipped[2] & lab.bit("saturated") and power_of(clipped) < power


@pytest.mark.parametrize("word_order", ["big"])
def test_pymodbustcp_reports_the_specs_exception_codes(server):
    _, drive_map, amp_map, client = server
    drive, amp = client(STAGE_UNIT), client(DETECTOR_UNIT)

    def refused(code, who, result):
        assert result in (None, False)  # a failed read / write; the code is kept
        assert (who.last_error, who.last_except) == (MB_EXCEPT_ERR, code)
        assert who.last_except_as_txt == SPEC_EXCEPTIONS[code]

    refused(2, drive, drive.write_single_register(drive_map.address("status"), 5))  # r only
    refused(2, drive, drive.read_holding_registers(20))  # not in the map
    refused(3, drive, drive.write_single_register(drive_map.address("command"), 99))
    refused(3, amp, amp.write_single_register(amp_map.address("gain_range"), 99))
    refused(1, drive, drive.read_coils(0))  # no coils
    refused(2, amp, amp.read_device_identification(read_code=4, object_id=0x80))  # absent
    absent = client(9)
    refused(11, absent, absent.read_holding_registers(0))  # no unit 9 behind the server
    assert drive.read_holding_registers(drive_map.address("status")) == [0]
