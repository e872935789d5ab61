"""A Modbus RTU link holds its serial port from its making to its close (drivers.port_lock):
while it is connected pymodbus's own exclusive open (pyserial's flock) and gonio's LCK file
keep another master and another gonio out, and once a connection is lost the hold's own flock
does until the link reconnects; once its drivers close, the port is free. A Modbus TCP link
holds its endpoint by name (`modbus-tcp://host:port`) against another gonio."""

import os

import pytest
from port_testkit import TRY_HOLD, elsewhere

from drivers.port_lock import PortInUse, hold

EXCLUSIVE_OPEN = """
import sys, serial
try:
    serial.Serial(sys.argv[1], exclusive=True)
except serial.SerialException as exc:
    print("refused:", exc)
else:
    print("opened")
"""
REFUSED = "refused: [Errno 11] Could not exclusively lock port"


def test_the_rtu_link_holds_its_port_while_its_drivers_are_open(rig):
    r = rig("rtu")
    path = r.server.endpoint
    assert r.stage.position() == 0.0  # connected: pymodbus's serial client holds the flock
    assert elsewhere(EXCLUSIVE_OPEN, path).startswith(REFUSED)
    assert elsewhere(TRY_HOLD, path).startswith(f"x: {path} is in use by process {os.getpid()} ")
    with pytest.raises(PortInUse, match=f"^x: {path} is in use: already opened by this gonio "
                                        "for device sample$"):
        hold(path, "x")
    r.step_aside()
    with hold(path, "x"):
        pass


def test_a_lost_rtu_connection_leaves_the_port_held_until_the_link_reconnects(rig):
    r = rig("rtu")
    path = r.server.endpoint
    assert r.stage.position() == 0.0
    r.stage.link._lose_connection()  # what a lost port does: pymodbus's client closes it
    assert elsewhere(EXCLUSIVE_OPEN, path).startswith(REFUSED)  # the hold's flock, not a gap
    assert r.stage.position() == 0.0  # reconnected: the flock handed over to pymodbus again
    assert elsewhere(EXCLUSIVE_OPEN, path).startswith(REFUSED)
    r.step_aside()
    assert elsewhere(EXCLUSIVE_OPEN, path) == "opened"


def test_a_tcp_link_holds_its_endpoint_by_name_against_another_gonio(rig):
    # a Modbus TCP server serves several masters, but one gonio at a time drives its units
    r = rig("tcp")
    name = f"modbus-tcp://{r.stage.link.endpoint}"
    assert r.stage.position() == 0.0
    assert elsewhere(TRY_HOLD, name).startswith(f"x: {name} is in use by process {os.getpid()} ")
    assert r.stage.position() == 0.0  # a lost and remade connection keeps the hold
    r.stage.link._lose_connection()
    assert r.stage.position() == 0.0
    assert elsewhere(TRY_HOLD, name).startswith(f"x: {name} is in use by process {os.getpid()} ")
    r.step_aside()
    assert elsewhere(TRY_HOLD, name) == "held"
