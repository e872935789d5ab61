"""The units on one RTU bus share one link however their port is written (a device file and a
/dev/serial/by-id symlink to it are one port: drivers.port_identity), and a unit asking for
another line than the link's (baud rate, parity, stop bits, timeouts) is one ValueError naming
both devices, leaving the link as it was."""

import pytest
from modbus_testkit import SECOND_STAGE_UNIT

from drivers.byte_link import LineSettings
from drivers.modbus_stage import ModbusStage
from drivers.modbus_transport import RTU_LINE, ModbusTimeouts

REPLY_S = 0.2  # the rig's


def test_a_unit_on_a_symlink_to_the_bus_shares_its_link(rig, tmp_path):
    r = rig("rtu", reply_s=REPLY_S)
    alias = tmp_path / "usb-FTDI_RS485-if00-port0"  # a /dev/serial/by-id name of the bus
    alias.symlink_to(r.server.endpoint)
    with ModbusStage("rtu", str(alias), SECOND_STAGE_UNIT, r.stage_map, name="arm_by_id",
                     timeouts=ModbusTimeouts(reply_s=REPLY_S)) as by_id:
        assert by_id.link is r.stage.link
        r.second.move_to(12.5)
        r.second.wait(10.0)
        assert by_id.position() == 12.5  # the same unit, reached through the alias
    assert r.stage.position() == 0.0  # the link outlives a unit that leaves it


@pytest.mark.parametrize("asked, differs", [
    (dict(line=LineSettings(9600, parity="even")), "baudrate 115200; arm2 gives baudrate 9600"),
    (dict(line=LineSettings(115200, parity="none", stopbits=2)),
     "parity 'even', stopbits 1; arm2 gives parity 'none', stopbits 2"),
    (dict(line=RTU_LINE, timeouts=ModbusTimeouts(reply_s=0.5)),
     "reply_s 0.2; arm2 gives reply_s 0.5"),
])
def test_a_unit_asking_for_another_line_is_refused_naming_both(rig, asked, differs):
    r = rig("rtu", reply_s=REPLY_S)
    path = r.server.endpoint
    asked = {"timeouts": ModbusTimeouts(reply_s=REPLY_S), **asked}
    with pytest.raises(ValueError) as refused:
        ModbusStage("rtu", path, SECOND_STAGE_UNIT, r.stage_map, name="arm2", **asked)
    assert str(refused.value) == (f"arm2: {path} is the line of sample, opened with {differs} "
                                  "(devices on one line must agree on its settings)")
    assert r.second.position() == 0.0  # the bus goes on as it was
