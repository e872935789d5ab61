"""A link that cannot be opened is one clean clause naming the port once, with what a lab can do
about it: a missing port (over pyserial and as an ASRL resource), a port this user may not
open (a real pty opened by a user without access: the `dialout` group), a USB instrument
pyvisa-py cannot find (a udev rule for its vendor id). The library's exception stays the
cause."""

import os
import re

import pytest
import serial

from drivers.pm100 import Pm100
from drivers.serial_transport import SerialPortError

NOBODY = 65534
USB_METER = "USB0::0x1313::0x8072::P0000404::INSTR"  # served and held by no other test


def opening(**link) -> SerialPortError:
    """The error opening a PM100 driver on `link` (a port or a resource) raises."""
    with pytest.raises(SerialPortError) as err:
        Pm100(name="pm100", timeout_s=0.2, **link)
    return err.value


def test_a_missing_port_is_named_once(tmp_path):
    missing = str(tmp_path / "ttyUSB0")
    err = opening(port=missing)
    assert str(err) == (f"pm100: serial port {missing} could not be opened: [Errno 2] No such "
                        f"file or directory")
    assert err.cause.errno == 2 and isinstance(err.cause.__cause__, serial.SerialException)


def test_a_missing_asrl_resource_is_named_once(tmp_path):
    resource = f"ASRL{tmp_path / 'ttyUSB0'}::INSTR"
    assert str(opening(resource=resource)) == (
        f"pm100: VISA resource {resource} could not be opened: [Errno 2] No such file or "
        f"directory")


def test_a_usb_instrument_that_is_not_found_may_be_absent_or_need_a_udev_rule():
    err = opening(resource=USB_METER)
    assert str(err).startswith(f"pm100: VISA resource {USB_METER} could not be opened: ")
    assert str(err).endswith(": the instrument may be absent (not plugged in, switched off) or "
                             "not accessible to this user (a udev rule for USB vendor 0x1313 "
                             "gives access; docs/real-bench.md)")
    assert err.cause.__cause__ is not None  # what pyvisa-py (or pyusb) raised


def opened_without_access(path: str) -> str:
    """The error a user without access to the device file `path` gets opening a PM100 driver
    on it: nobody's, in a forked child, when the test runs as root (who may open anything);
    otherwise this user's, with the file's mode cleared."""
    def attempt() -> str:
        try:
            Pm100(port=path, name="pm100", timeout_s=0.2).close()
        except SerialPortError as exc:
            return f"{exc}\n{exc.cause.errno}"
        return "opened"

    if os.geteuid() != 0:
        os.chmod(path, 0)
        return attempt()
    readable, writable = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child only drops its rights, tries, reports and leaves
        try:
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            os.write(writable, attempt().encode())
        finally:
            os._exit(0)
    os.close(writable)
    with os.fdopen(readable, "rb") as pipe:
        said = pipe.read().decode()
    os.waitpid(pid, 0)
    return said


def test_a_port_this_user_may_not_open_names_the_dialout_group():
    leader, follower = os.openpty()
    try:
        path = os.ttyname(follower)
        message, code = opened_without_access(path).rsplit("\n", 1)
    finally:
        os.close(leader)
        os.close(follower)
    assert code == "13"
    assert message == (f"pm100: serial port {path} could not be opened: [Errno 13] Permission "
                       f"denied: this user needs the `dialout` group (sudo usermod -aG dialout "
                       f"USER, then log in again) or a udev rule giving it the port")
    assert len(re.findall(re.escape(path), message)) == 1
