"""One device written two ways is one port (drivers.port_identity, drivers.port_lock): a port
held by its path is refused to an ASRL resource naming it with or without `::INSTR`, through
a symlink whose name has colons (/dev/serial/by-path/...), and the other way round; a USB
resource with its ids in hex and in decimal and its serial number in either case, and a TCPIP
resource by host name and by address, are one lock, as is a Modbus TCP server; an ASRL
resource whose port cannot be held is one error, the transport's, before anything opens; a
serial port's name costs no PyVISA import."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from port_testkit import ENV, HOLDER, child, said

from drivers.port_identity import port_key, tcp_url
from drivers.port_lock import PortInUse, Unholdable, hold
from drivers.serial_transport import SerialLineTransport, SerialPortError

BY_PATH = "pci-0000:00:14.0-usb-0:2:1.0-port0"  # a /dev/serial/by-path name: colons in it


@pytest.mark.parametrize(("held", "asked"), [
    ("{path}", "ASRL{path}"),  # ::INSTR implied
    ("ASRL{path}", "{path}"),
    ("{path}", "ASRL{alias}::INSTR"),
    ("ASRL{alias}::INSTR", "ASRL{path}::INSTR"),
])
def test_a_port_written_another_way_is_the_same_port(pty, tmp_path, held, asked):
    _, path = pty
    alias = tmp_path / BY_PATH
    alias.symlink_to(path)
    with child(HOLDER, held.format(path=path, alias=alias)) as first:
        assert said(first) == "held"
        with pytest.raises(PortInUse) as refused:
            hold(asked.format(path=path, alias=alias), "pm100")
        assert refused.value.holder_pid == first.pid


@pytest.mark.parametrize(("held", "asked"), [
    ("USB0::0x1313::0x8072::P2000000::INSTR", "USB0::4883::32882::p2000000::INSTR"),
    ("USB::0x1313::0x8072::P2000000", "usb0::0x1313::0x8072::P2000000::0::INSTR"),
    ("TCPIP::localhost::5025::SOCKET", "TCPIP0::127.0.0.1::5025::SOCKET"),
])
def test_a_resource_written_another_way_is_the_same_resource(tmp_path, monkeypatch, held,
                                                             asked):
    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path))
    with child(HOLDER, held, env={**ENV, "GONIO_LOCK_DIR": str(tmp_path)}) as first:
        assert said(first) == "held"
        with pytest.raises(PortInUse) as refused:
            hold(asked, "pm100")
        assert refused.value.holder_pid == first.pid
        with hold("USB0::0x1313::0x8072::P2000001::INSTR", "other"):
            pass  # another serial number is another meter


@pytest.mark.parametrize(("resource", "why"), [
    ("ASRL1::INSTR", "ASRL1 names no device file: write the port's path, as in "
                     "ASRL/dev/ttyUSB0::INSTR"),
    ("ASRL{missing}::INSTR", "[Errno 2] No such file or directory"),  # the path named once
])
def test_an_asrl_resource_whose_port_cannot_be_held_is_one_error(tmp_path, resource, why):
    missing = tmp_path / "ttyUSB9"
    resource, why = resource.format(missing=missing), why.format(missing=missing)
    with pytest.raises(Unholdable, match=f"^pm100: cannot hold {re.escape(resource)}: "):
        hold(resource, "pm100")
    with pytest.raises(SerialPortError) as failed:  # the transport's one error: not opened
        SerialLineTransport(resource=resource, name="pm100")
    assert str(failed.value) == f"pm100: VISA resource {resource} could not be opened: {why}"


@pytest.mark.parametrize("spelt", ["modbus-tcp://localhost:1502", "modbus-tcp://LOCALHOST:1502",
                                   "modbus-tcp://127.0.0.1:1502"])
def test_a_modbus_tcp_server_by_name_or_address_is_one_endpoint(spelt):
    assert port_key(spelt) == "modbus-tcp://127.0.0.1:1502"
    assert port_key(tcp_url("modbus-tcp", "::1", 502)) == "modbus-tcp://[::1]:502"
    with hold("modbus-tcp://127.0.0.1:1502", "first"), \
            pytest.raises(PortInUse, match="already opened by this gonio for device first"):
        hold(spelt, "second")


def test_a_serial_ports_name_costs_no_visa_import():
    # only a string that may be a resource goes to PyVISA: a config of serial ports, and every
    # port its run holds, never import it
    code = ("import sys; from drivers.port_identity import port_key; "
            "port_key('/dev/ttyUSB0'); port_key('socket://localhost:4001'); "
            "print('pyvisa' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=ENV, check=True).stdout.strip() == "False"
