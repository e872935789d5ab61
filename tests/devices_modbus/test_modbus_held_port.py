"""A Modbus RTU link holds its serial port from its making to its close (drivers.port_lock):
while it is connected pymodbus's own exclusive open (pyserial's flock) and gonio's LCK file
keep another master and another gonio out; once its drivers close, the port is free."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.port_lock import PortInUse, hold

ROOT = Path(__file__).resolve().parents[2]
EXCLUSIVE_OPEN = """
import sys, serial
try:
    serial.Serial(sys.argv[1], exclusive=True)
except serial.SerialException as exc:
    print("refused:", exc)
"""


def test_the_rtu_link_holds_its_port_while_its_drivers_are_open(rig):
    r = rig("rtu")
    path = r.server.endpoint
    assert r.stage.position() == 0.0  # connected: pymodbus's serial client holds the flock
    other = subprocess.run([sys.executable, "-c", EXCLUSIVE_OPEN, path], capture_output=True,
                           text=True, timeout=30, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert other.stdout.startswith("refused: [Errno 11] Could not exclusively lock port"), \
        other.stderr
    with pytest.raises(PortInUse, match=f"^x: {path} is in use by process {os.getpid()} "):
        hold(path, "x")
    r.step_aside()
    with hold(path, "x"):
        pass
