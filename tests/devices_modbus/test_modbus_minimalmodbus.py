"""minimalmodbus (Modbus RTU for instruments on a serial line) drives both emulators on the RTU
pty as a lab's own script would, from the register map read with tomllib: identity strings,
position and status, a move polled to its end on the drive's virtual clock, the amplifier's
power in a fixed gain range, and exception replies as the library reports them."""

import pytest
import serial
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

minimalmodbus = pytest.importorskip(
    "minimalmodbus", reason="minimalmodbus is not installed (pip install -e '.[clients]')")

pytestmark = pytest.mark.thirdparty


@pytest.fixture
def bus(rig, word_order):
    """(rig, stage map, detector map, byte order constant, instrument maker): the emulators
    on the RTU pty, the drive on a frozen clock, the bus opened as a script opens it."""
    r = rig("rtu", word_order, clock=VirtualClock(0.0))
    r.step_aside()  # gonio's drivers hold the port while open
    order = (minimalmodbus.BYTEORDER_BIG if word_order == "big"
             else minimalmodbus.BYTEORDER_LITTLE_SWAP)  # CD AB: low word first
    with serial.Serial(r.server.endpoint, 115200, timeout=0.5) as port:
        yield (r, LabMap.load(r.stage_map), LabMap.load(r.detector_map), order,
               lambda unit: minimalmodbus.Instrument(port, unit))


def test_minimalmodbus_reads_identity_position_and_limits(bus):
    r, drive_map, amp_map, order, instrument = bus
    drive, amp = instrument(STAGE_UNIT), instrument(DETECTOR_UNIT)
    assert ascii_of(drive.read_string(*drive_map.identity("vendor"))) == drive_map.doc["vendor"]
    assert ascii_of(drive.read_string(*drive_map.identity("model"))) == drive_map.doc["name"]
    serials = {ascii_of(drive.read_string(*drive_map.identity("serial"))),
               ascii_of(amp.read_string(*amp_map.identity("serial"), functioncode=4))}
    assert len(serials) == 2 and "" not in serials  # one serial per unit
    assert ascii_of(amp.read_string(*amp_map.identity("model"), functioncode=4)) == \
        amp_map.doc["name"]

    def read_deg(name):
        return drive_map.value(name, drive.read_long(drive_map.address(name), signed=True,
                                                     byteorder=order))

    assert read_deg("actual_position") == 0.0
    assert (read_deg("limit_negative"), read_deg("limit_positive")) == (-95.0, 95.0)
    assert drive.read_register(drive_map.address("status")) == 0  # at rest, not homed
    assert r.stage_emu.axis_position_deg() == 0.0


def test_minimalmodbus_sets_speed_and_moves_to_a_target_polled_to_its_end(bus):
    r, lab, _, order, instrument = bus
    drive = instrument(STAGE_UNIT)
    drive.write_long(lab.address("velocity"), lab.raw("velocity", 12.5), byteorder=order)
    drive.write_long(lab.address("acceleration"), lab.raw("acceleration", 50.0),
                     byteorder=order)
    drive.write_long(lab.address("target_position"), lab.raw("target_position", -30.0),
                     signed=True, byteorder=order)
    drive.write_register(lab.address("command"), lab.command("start"), functioncode=6)
    polls, positions = poll_move(
        lab, lambda: drive.read_register(lab.address("status")),
        lambda: lab.value("actual_position", drive.read_long(
            lab.address("actual_position"), signed=True, byteorder=order)),
        r.stage_emu.axis.clock)
    assert polls == moving_polls(30.0, 12.5, 50.0) == 11  # 7 at the power-on 20 deg/s
    check_move(positions, 0.0, -30.0)
    assert drive.read_register(lab.address("fault_code")) == 0
    assert r.stage_emu.axis_position_deg() == -30.0


def test_minimalmodbus_reads_the_power_in_a_fixed_gain_range(bus):
    r, _, lab, order, instrument = bus
    amp = instrument(DETECTOR_UNIT)
    for name, value in (("autorange", 0), ("gain_range", 4), ("averaging", 8)):
        amp.write_register(lab.address(name), value, functioncode=6)
    assert amp.read_register(lab.address("averaging")) == 8
    power = amp.read_float(lab.address("reading"), functioncode=4, byteorder=order)
    status, in_use, fault = amp.read_registers(lab.address("status"), 3, functioncode=4)
    assert (status, in_use, fault) == (0, 4, 0)
    assert power == pytest.approx(1e-5, rel=5e-3)  # ConstantPower(1e-5), read noise 1e-3
    assert power < lab.doc["gain_ranges"]["full_scale_w"][in_use]
    amp.write_register(lab.address("gain_range"), 2, functioncode=6)  # 1e-6 W full scale
    clipped = amp.read_float(lab.address("reading"), functioncode=4, byteorder=order)
    assert amp.read_register(lab.address("status"), functioncode=4) & lab.bit("saturated")
    assert clipped < power


@pytest.mark.parametrize("word_order", ["big"])
def test_minimalmodbus_reports_the_specs_exception_codes(bus):
    _, drive_map, amp_map, _, instrument = bus
    drive, amp = instrument(STAGE_UNIT), instrument(DETECTOR_UNIT)
    # minimalmodbus reads for the length of the reply it asked for, so an exception reply
    # (5 bytes) ends at the port's timeout: kept short, each refusal costs it once
    drive.serial.timeout = 0.2

    def refused(code, call, *args, **kwargs):
        with pytest.raises(minimalmodbus.IllegalRequestError) as err:
            call(*args, **kwargs)
        assert str(err.value) == f"Slave reported {SPEC_EXCEPTIONS[code]}"

    refused(2, drive.write_register, drive_map.address("status"), 5, functioncode=6)  # r only
    refused(2, drive.read_register, 20)  # not in the map
    refused(3, drive.write_register, drive_map.address("command"), 99, functioncode=6)
    refused(3, amp.write_register, amp_map.address("gain_range"), 99, functioncode=6)
    refused(1, drive.read_bit, 0, functioncode=2)  # no discrete inputs
    with pytest.raises(minimalmodbus.NoResponseError):
        instrument(9).read_register(0)  # no unit 9 on the bus: silence
    assert drive.read_register(drive_map.address("status")) == 0  # the line is in step
