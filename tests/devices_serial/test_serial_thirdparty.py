"""Third-party clients drive the emulators with the manuals' command strings: socat, and a
plain pyserial session that uses none of gonio's drivers."""

import math
import os
import shutil
import subprocess

import pytest
import serial

from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator


def need(tool):
    """The tool's path; fail in CI (CI=true) when it is missing, skip elsewhere."""
    path = shutil.which(tool)
    if path is None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"{tool} is not installed and CI=true: .ci/run must install it")
        pytest.skip(f"{tool} is not installed (apt-get install {tool}); CI installs it")
    return path


def socat(endpoint, data: bytes) -> bytes:
    """Send data to the pty with socat (raw, no echo) and collect what comes back."""
    result = subprocess.run(
        [need("socat"), "-t", "0.5", "-", f"{endpoint},raw,echo=0"],
        input=data, capture_output=True, timeout=10, check=True,
    )
    return result.stdout


@pytest.fixture
def esp():
    with EspEmulator(VirtualClock(math.inf), {1: {}, 2: {}}) as emu:
        yield emu
    assert emu.server.handler_errors == []


@pytest.fixture
def pm100():
    with Pm100Emulator(ConstantPower(1e-6), seed=1) as emu:
        yield emu
    assert emu.server.handler_errors == []


@pytest.mark.thirdparty
def test_socat_drives_the_esp(esp):
    out = socat(esp.endpoint,
                b"VE?\r1MO\r1MO?\r1PA30\r1TP\r1MD?\r2PR-12.5;2TP?\r1PA200\rTB?\r2MO?\r")
    lines = out.split(b"\r\n")
    assert lines[:5] == [b"ESP301 Version 3.0.2 (emulated)", b"1", b"30.00000", b"1", b"0.00000"]
    code, stamp, text = lines[5].split(b", ")
    assert (code, text) == (b"213", b"MOTOR NOT ENABLED") and stamp.isdigit()
    assert lines[6:] == [b"0", b""]
    assert esp.axis_position_deg(1) == 30.0
    assert list(esp.errors)[0][0] == 106  # 1PA200 is past the +170 software limit


@pytest.mark.thirdparty
def test_socat_drives_the_pm100(pm100):
    out = socat(pm100.endpoint, b"*IDN?\nSYST:SENS:IDN?\nSENS:CORR:WAV 850\r\n"
                b"SENS:CORR:WAV?\nMEAS:POW?\nSYST:ERR?\n")
    lines = out.decode().split("\n")
    assert lines[0].startswith("Thorlabs,PM100D")
    assert len(lines[1].split(",")) == 6
    assert lines[2] == "8.500000E+02"
    assert float(lines[3]) == pytest.approx(1e-6, rel=0.05)
    assert lines[4:] == ['0,"No error"', ""]


def test_plain_pyserial_session_with_the_manuals_strings(esp, pm100):
    with serial.Serial(esp.endpoint, 19200, timeout=1.0) as port:
        port.write(b"1MO;1VA10;1AC40;1PA5;1WS;1TP?\r")
        assert port.read_until(b"\r\n") == b"5.00000\r\n"
        port.write(b"3TP\rTE?\r")
        assert port.read_until(b"\r\n") == b"9\r\n"
    with serial.Serial(pm100.endpoint, 115200, timeout=1.0) as port:
        port.write(b"SENSE:POWER:RANGE:AUTO OFF;:SENS:POW:RANG 1E-5;RANG?\n")
        assert port.read_until(b"\n") == b"1.000000E-05\n"
        port.write(b"sens:aver:coun 4;coun?;:read?\n")
        count, power = port.read_until(b"\n").decode().strip().split(";")
        assert count == "4" and float(power) == pytest.approx(1e-6, rel=0.05)
