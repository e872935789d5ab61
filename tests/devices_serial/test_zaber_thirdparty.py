"""A third-party client drives the Zaber emulator: Zaber's own zaber.serial library (its
AsciiSerial / AsciiDevice / AsciiAxis classes), which shares no code with gonio's driver."""


import pytest
from zaber.serial import AsciiCommand, AsciiDevice, AsciiSerial

from sim.devices.motion import VirtualClock
from sim.devices.zaber import ZaberEmulator


@pytest.fixture
def chain():
    """Device 1 with one axis, device 2 with two, on one port, at 50x real time."""
    axes = {(1, 1): {}, (2, 1): {}, (2, 2): {"limits_deg": (6.0, 354.0), "homed": False}}
    with ZaberEmulator(VirtualClock(50.0), axes) as emu, \
            AsciiSerial(emu.endpoint, baud=115200, timeout=2) as port:
        yield emu, port
    assert emu.server.handler_errors == []


@pytest.mark.thirdparty
def test_zaber_serial_homes_moves_and_reads_positions(chain):
    emu, port = chain
    device = AsciiDevice(port, 1)
    reply = device.home()  # "/1 0 home", then polls until IDLE
    assert (reply.reply_flag, reply.device_address, reply.axis_number) == ("OK", 1, 0)
    device.move_abs(64000)  # 15 degrees
    assert device.get_position() == 64000
    assert emu.axis_position_deg((1, 1)) == pytest.approx(15.0)
    device.move_rel(-4000)
    assert device.get_status() == "IDLE" and device.get_position() == 60000


@pytest.mark.thirdparty
def test_zaber_serial_drives_axes_of_a_chained_device(chain):
    emu, port = chain
    device = AsciiDevice(port, 2)
    arm = device.axis(2)
    assert arm.send("get pos").warning_flag == "WR"
    arm.home()
    assert arm.get_position() == 25600  # the home search ends on limit.min, 6 degrees
    arm.move_abs(768000)  # 180 degrees
    assert arm.get_position() == 768000 and device.axis(1).get_position() == 0
    rejected = arm.send("move abs 99999999")
    assert (rejected.reply_flag, rejected.data) == ("RJ", "BADDATA")


@pytest.mark.thirdparty
def test_zaber_serial_checks_checksums_and_message_ids(chain):
    emu, port = chain
    device = AsciiDevice(port, 1)
    assert device.send("set comm.checksum 1").checksum is not None
    reply = device.send(AsciiCommand(1, 1, 42, "get maxspeed"))  # message id 42
    assert (reply.message_id, reply.data) == (42, "139810")
    port.write("/get system.serial")  # every device of the chain answers
    assert sorted(port.read().data for _ in range(2)) == ["120001", "120002"]
